"""Where the experiments find the development photos (issue 59): ``--photos``, else
$BALLTRACK_PHOTOS, else shared/data beside the repository; no help names a machine's folder."""

import pytest

from balltrack.experiments import cli, detector_outputs, detector_speed, real_photos
from balltrack.experiments.base import PHOTOS_VARIABLE, development_photos, shown_path
from tests.harness import REPO
from tests.unit.test_real_photos import write_set

BESIDE_THE_REPOSITORY = REPO.parent / "shared" / "data"


def test_the_option_comes_first_then_the_variable_then_the_folder_beside_the_repository(monkeypatch, tmp_path):
    monkeypatch.delenv(PHOTOS_VARIABLE, raising=False)
    assert development_photos() == BESIDE_THE_REPOSITORY
    monkeypatch.setenv(PHOTOS_VARIABLE, "")
    assert development_photos() == BESIDE_THE_REPOSITORY
    monkeypatch.setenv(PHOTOS_VARIABLE, str(tmp_path / "named"))
    assert development_photos() == tmp_path / "named"
    assert development_photos(str(tmp_path / "given")) == tmp_path / "given"
    assert development_photos(tmp_path / "given") == tmp_path / "given"


def help_of(main, capsys) -> str:
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("module", [cli, detector_speed, real_photos, detector_outputs])
def test_no_help_nor_docstring_names_a_machines_folder(module, monkeypatch, capsys):
    monkeypatch.delenv(PHOTOS_VARIABLE, raising=False)
    for text in (module.__doc__, help_of(module.main, capsys)):
        assert "/work/" not in text and str(BESIDE_THE_REPOSITORY) not in text


@pytest.mark.parametrize("module", [cli, detector_speed])
def test_the_help_says_where_the_photos_are_looked_for(module, capsys):
    text = " ".join(help_of(module.main, capsys).split())
    assert f"${PHOTOS_VARIABLE}, else ../shared/data beside the repository" in text


def test_all_takes_the_photos_the_variable_names(monkeypatch, tmp_path):
    write_set(tmp_path / "photos" / "one_set", [[(200.0, 240.0, 25.0)]])
    monkeypatch.setenv(PHOTOS_VARIABLE, str(tmp_path / "photos"))
    assert cli.parse(["all", "--out", str(tmp_path / "out")]).photos == tmp_path / "photos"
    assert cli.parse(["all", "--out", str(tmp_path / "out"), "--photos", str(tmp_path / "photos" / "one_set")]
                     ).photos == tmp_path / "photos" / "one_set"


def test_a_variable_naming_no_photos_is_refused(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv(PHOTOS_VARIABLE, str(tmp_path / "missing"))
    with pytest.raises(SystemExit) as exit_info:
        cli.parse(["all", "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2 and f"${PHOTOS_VARIABLE}: {tmp_path / 'missing'}" in capsys.readouterr().err
    assert detector_speed.main(["--frames", "3", "--repeats", "10"]) == 2
    assert f"{tmp_path / 'missing'}: not a folder" in capsys.readouterr().err


def test_reports_show_the_photos_beside_the_repository_by_a_relative_path():
    assert shown_path(BESIDE_THE_REPOSITORY) == "../shared/data"
    assert shown_path(REPO.parent / "elsewhere" / "photos") == "../elsewhere/photos"
    assert shown_path("/proc/balltrack-photos") == "/proc/balltrack-photos"  # not beside it: as it is

"""experiments/detector_outputs.py: the detector's outputs recorded, then compared."""

import json

import pytest

from balltrack.experiments import detector_outputs


def test_the_same_detector_gives_the_same_outputs_and_a_changed_output_is_named(tmp_path, capsys):
    recorded = tmp_path / "outputs.json"
    assert detector_outputs.main(["record", str(recorded), "--renders", "3"]) == 0
    content = json.loads(recorded.read_text())
    assert [frame["frame"] for frame in content["frames"]] == ["render 0", "render 1", "render 2"]
    assert any(frame["detections"] for frame in content["frames"])
    assert detector_outputs.main(["compare", str(recorded)]) == 0
    assert "3 frames, 0 differ" in capsys.readouterr().out
    # one score a thousandth off, as a change to the detector would make it
    changed = next(frame for frame in content["frames"] if frame["detections"])
    changed["detections"][0][3] += 0.001
    recorded.write_text(json.dumps(content))
    assert detector_outputs.main(["compare", str(recorded)]) == 1
    out = capsys.readouterr().out
    assert "3 frames, 1 differ" in out and f"{changed['frame']}: detections differ" in out


def test_bad_files_and_arguments_get_one_line(tmp_path, capsys):
    assert detector_outputs.main(["compare", str(tmp_path / "missing.json")]) == 2
    (tmp_path / "other.json").write_text('{"something": "else"}')
    assert detector_outputs.main(["compare", str(tmp_path / "other.json")]) == 2
    (tmp_path / "text.json").write_text("not json")
    assert detector_outputs.main(["compare", str(tmp_path / "text.json")]) == 2
    assert detector_outputs.main(["record", str(tmp_path / "x.json"), "--recording", str(tmp_path / "none.mcap")]) == 2
    errors = capsys.readouterr().err.strip().splitlines()
    assert len(errors) == 4 and all(line.startswith("detector_outputs: ") for line in errors)


def test_record_without_frames_is_refused():
    with pytest.raises(SystemExit) as exited:
        detector_outputs.main(["record", "outputs.json"])
    assert exited.value.code == 2


def test_photos_are_named_by_their_own_files_when_one_cannot_be_read(tmp_path):
    import cv2
    import numpy as np

    (tmp_path / "a.png").write_bytes(b"not an image")
    cv2.imwrite(str(tmp_path / "b.png"), np.full((48, 64, 3), 90, np.uint8))
    frames = detector_outputs.frames_of({"photos": str(tmp_path)})
    assert [name for name, _ in frames] == ["photo b.png"]
    assert frames[0][1].shape == (480, 640, 3)


def test_sigterm_stops_a_run_with_one_line(tmp_path):
    import signal
    import sys

    from tests.harness import Process

    run = Process([sys.executable, "-m", "balltrack.experiments.detector_outputs", "record",
                   str(tmp_path / "outputs.json"), "--renders", "3000"], tmp_path / "run.log")
    run.wait_for_signal_handler(signal.SIGTERM, timeout=60)
    assert run.stop() == 1
    assert run.output() == "detector_outputs: stopped by a signal\n"
    assert not (tmp_path / "outputs.json").exists()

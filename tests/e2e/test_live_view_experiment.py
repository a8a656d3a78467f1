"""``balltrack experiment live_view`` end to end with two changes of light: the whole system,
``balltrack view`` and both browsers; every change seen by each, its figures under stable
names. How fast is the experiment's own business (a timing, judged on a quiet machine), not
this test's."""

import json

import pytest

pytest.importorskip("rerun")
pytest.importorskip("websockets")

from balltrack.experiments import cli  # noqa: E402
from balltrack.experiments.browser import CHROMIUM  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900),
              pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (deploy/setup.sh installs it)")]


def test_live_view_times_each_change_with_each_renderer(tmp_path):
    assert cli.main(["live_view", "--frames", "2", "--out", str(tmp_path), "--no-progress"]) == 0

    results = json.loads((tmp_path / "results.json").read_text())
    assert results["experiments"]["live_view"]["mode"] == "zenoh"
    figures = results["figures"]
    for renderer, webgl in (("mesa", "llvmpipe"), ("swiftshader", "SwiftShader")):
        assert webgl in figures[f"live_view/{renderer}/webgl"]
        assert figures[f"live_view/{renderer}/changes"] == 2
        assert figures[f"live_view/{renderer}/seen"] == 2, figures
        assert figures[f"live_view/{renderer}/not_seen"] == 0
        # Each change reached the page after it reached the system's own annotated frames.
        pairs = list(zip(figures[f"live_view/{renderer}/each_s"], figures[f"live_view/{renderer}/image_out_each_s"]))
        assert len(pairs) == 2 and any(frames is not None for _, frames in pairs)
        assert all(page > frames > 0 for page, frames in pairs if frames is not None)
        assert figures[f"live_view/{renderer}/page_frames_per_s"] > 0
    assert [goal["name"] for goal in results["goals"]] == ["live_view/change_shown"]
    assert (tmp_path / "live_view" / "page-mesa.png").is_file()

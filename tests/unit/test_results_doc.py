"""docs/results.md's generator: a run folder's results.json becomes a dated document with the
machine's speed, each experiment's goals with PASS/MISS and its main figures."""

import json

import pytest

from balltrack.experiments import results_doc
from balltrack.experiments.base import ExperimentResult, write_outputs

MACHINE = {"python_loop_ms": 41.25, "opencv_blur_ms": 0.375, "encode_us": 9.4, "encode_after_idle_us": 101.0}


def write_run(folder):
    first = ExperimentResult("range", "Detection range", quick=True, date="2030-01-02 03:04",
                             command="balltrack experiment range --quick --out runs/r", machine=dict(MACHINE))
    first.figure("detection_rate", 0.97)
    first.goal("detection", "detection from 0.1 to 5 m", ">= 95 %", "97 %", True)
    first.goal("error", "median distance error up to 3.5 m", "<= 3 %", "4.1 %", False)
    first.compare("detected up to", "3.5 m", "5 m")
    first.notes.append("lowest rate at 5 m")
    # (an entry written before dates and the machine entry: its machine figures are figures)
    second = ExperimentResult("latency", "Reaction time", mode="zenoh", date="")
    for name, value in MACHINE.items():
        second.figure(f"machine/{name}", value * 2)
    second.notes.append("Machine speed in this run: ...")
    write_outputs(folder, [first, second], ["range", "latency"])
    data = json.loads((folder / "results.json").read_text())
    del data["experiments"]["latency"]["machine"]
    (folder / "results.json").write_text(json.dumps(data))


def test_the_document_has_dates_machine_goals_and_figures(tmp_path):
    write_run(tmp_path / "run")
    out = tmp_path / "docs" / "results.md"
    assert results_doc.main([str(tmp_path / "run"), "--out", str(out)]) == 0
    text = out.read_text()
    assert "covers 2 experiments: `range` (quick), `latency`" in text
    assert "balltrack experiment range --quick --out runs/r\n" in text
    assert "balltrack experiment latency --out " in text  # (no command recorded: the one that reruns it)
    assert f"python -m balltrack.experiments.results_doc {tmp_path / 'run'} --out {out}" in text
    assert "| [range](#range) | 2030-01-02 03:04 | yes | in-process | 41.2 | 0.38 | 9 | 101 | 1/2 PASS |" in text
    latency_row = next(line for line in text.splitlines() if line.startswith("| [latency]"))
    assert "(file)" in latency_row and "| 82.5 | 0.75 | 19 | 202 | - |" in latency_row
    assert "| detection from 0.1 to 5 m | >= 95 % | 97 % | PASS |" in text
    assert "| median distance error up to 3.5 m | <= 3 % | 4.1 % | **MISS** |" in text
    assert "| detected up to | 3.5 m | 5 m |" in text
    assert "lowest rate at 5 m" in text
    assert "Machine speed in this run" not in text


def test_without_out_it_prints_the_document(tmp_path, capsys):
    write_run(tmp_path)
    assert results_doc.main([str(tmp_path)]) == 0
    assert capsys.readouterr().out.startswith("# Results\n")


def test_a_folder_without_results_is_refused_in_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        results_doc.main([str(tmp_path)])
    assert stop.value.code == 2
    assert capsys.readouterr().err.strip().endswith("results.json: no such file "
                                                    f"(run balltrack experiment NAME --out {tmp_path} first)")

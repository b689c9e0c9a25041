"""benchmarks/wait_ratio.py's bookkeeping: per-file seconds from a pytest JUnit report, ratios over the files both
commits have, and its one-line error on bad input (the timing itself is the benchmark's, not a test's)."""
import pytest

JUNIT = """<?xml version="1.0" encoding="utf-8"?><testsuites><testsuite name="pytest">
<testcase classname="chapters.06_ppo.md" name="Cell 0" file="chapters/06_ppo.md" line="0" time="5.25" />
<testcase classname="chapters.06_ppo.md" name="Cell 1" file="chapters/06_ppo.md" line="0" time="0.75" />
<testcase classname="tests.test_iqm" name="test_a" file="tests/test_iqm.py" line="11" time="2.0" />
<testcase classname="tests.test_iqm" name="test_b" file="tests/test_iqm.py" line="20" time="1.5" />
</testsuite></testsuites>"""


def test_seconds_per_file_from_a_junit_report(tmp_path, script_module):
    report = tmp_path / "report.xml"
    report.write_text(JUNIT)
    seconds = script_module("benchmarks/wait_ratio.py").test_file_seconds(report)
    assert seconds == pytest.approx({"chapters/06_ppo.md": 6.0, "tests/test_iqm.py": 3.5})


def test_the_ratio_counts_only_the_files_both_commits_have(script_module):
    ratio = script_module("benchmarks/wait_ratio.py").ratio_over_common(
        {"a.py": 10.0, "b.md": 30.0, "gone.py": 99.0}, {"a.py": 5.0, "b.md": 15.0, "new.md": 50.0})
    assert (ratio["files"], ratio["base_seconds"], ratio["head_seconds"]) == (2, 40.0, 20.0)
    assert ratio["ratio"] == pytest.approx(0.5)
    assert ratio["only_head"] == {"new.md": 50.0} and ratio["only_base"] == {"gone.py": 99.0}
    assert ratio["per_file"]["b.md"] == {"base": 30.0, "head": 15.0}


def test_an_unknown_stage_is_one_line(monkeypatch, script_module):
    with pytest.raises(SystemExit) as stop:
        script_module("benchmarks/wait_ratio.py").main(["--stages", "tests,docs"])
    assert "--stages takes tests and/or book" in str(stop.value.code)


def test_the_readme_quotes_the_recorded_wait():
    import json
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    record = json.loads((root / "results" / "benchmarks" / "wait-ratio.json").read_text())
    readme = " ".join((root / "README.md").read_text().split())
    tests, book = (record["stages"][s]["head"]["wall_seconds"] for s in ("tests", "book"))
    assert f"the whole run takes about five minutes ({tests:.0f} s)" in readme
    assert f"the book build below about five more ({book:.0f} s)" in readme
    assert "Xeon" in record["machine"]["cpu_model"] and "AVX-512" in record["machine"]["cpu_model"]  # "Intel Xeon"

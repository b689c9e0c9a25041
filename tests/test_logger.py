import numpy as np
import pytest

from rlcore.logger import CSVLogger, read_csv


def test_rows_round_trip(tmp_path):
    path = tmp_path / "progress.csv"
    with CSVLogger(path) as log:
        log.log(step=1, episode_return=-1.5)
        log.log(step=2, episode_return=np.float32(2.25))
    cols = read_csv(path)
    np.testing.assert_array_equal(cols["step"], [1, 2])
    np.testing.assert_allclose(cols["episode_return"], [-1.5, 2.25])


def test_reopening_appends_instead_of_overwriting(tmp_path):
    path = tmp_path / "progress.csv"
    with CSVLogger(path, ["step", "r"]) as log:
        log.log(step=1, r=0.0)
    with CSVLogger(path, ["step", "r"]) as log:  # a resumed run
        log.log(step=2, r=1.0)
    assert path.read_text().splitlines() == ["step,r", "1,0.0", "2,1.0"]


def test_rows_are_flushed_immediately(tmp_path):
    path = tmp_path / "progress.csv"
    log = CSVLogger(path)
    log.log(step=1)
    assert path.read_text().splitlines() == ["step", "1"]  # visible before close
    log.close()


def test_mismatched_columns_are_errors(tmp_path):
    path = tmp_path / "progress.csv"
    with CSVLogger(path, ["step"]) as log:
        with pytest.raises(ValueError, match="not in"):
            log.log(step=1, extra=2)
    with pytest.raises(ValueError, match="has columns"):
        CSVLogger(path, ["other"])


def test_text_columns_stay_text(tmp_path):
    path = tmp_path / "p.csv"
    with CSVLogger(path) as log:
        log.log(name="a", v=1)
    assert read_csv(path)["name"].tolist() == ["a"]
    assert read_csv(tmp_path / "p.csv")["v"].dtype == float


def test_drop_rows_after_removes_only_the_rows_past_the_step(tmp_path):
    from rlcore.logger import drop_rows_after

    path = tmp_path / "eval.csv"
    with CSVLogger(path, ["step", "r"]) as log:
        for step in (100, 200, 300, 400):
            log.log(step=step, r=float(step))
    assert drop_rows_after(path, 250) == 2
    assert list(read_csv(path)["step"]) == [100, 200]
    assert drop_rows_after(path, 250) == 0

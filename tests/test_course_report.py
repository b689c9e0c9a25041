"""The report's DDPG tables as printed (rlbook.course_report) against the experiments that encode them."""

import pytest

from rlbook import REPORT_DDPG, get_experiment
from rlcore.ddpg import Config
from rlbook.course_report import (REPORT_DDPG_HUMANOID_TABLES, REPORT_DDPG_TABLES, REPORT_NAMES,
                                  report_overrides, report_steps)


def test_report_overrides_names_every_setting_in_rlcores_terms():
    table = REPORT_DDPG_TABLES["hopper"]
    o = report_overrides(table)
    assert set(o) == {field for _, field in REPORT_NAMES.values()}
    assert set(o) <= set(Config.__dataclass_fields__)
    assert o["hidden"] == (512,) and o["batch_size"] == 64 and o["reward_scale"] == 0.5 and o["tau"] == 0.001
    assert report_overrides(REPORT_DDPG_HUMANOID_TABLES["large"])["hidden"] == (1024, 1024)
    assert report_steps(table) == 400_000
    with pytest.raises(KeyError):
        report_overrides({"memory": 1})


def test_ddpg_report_experiment_is_tables_1_to_3():
    specs = {spec.name: spec for spec in get_experiment("ddpg-report").runs}
    assert set(specs) == set(REPORT_DDPG_TABLES)
    for name, table in REPORT_DDPG_TABLES.items():
        spec = specs[name]
        assert spec.algo == "ddpg" and spec.env_id.endswith("-v5")
        assert spec.steps == report_steps(table) == REPORT_DDPG[spec.env_id][0], name
        assert spec.overrides["exploration"] == "gaussian"
        for field, value in report_overrides(table).items():
            assert spec.overrides[field] == value, (name, field)
        Config(**spec.overrides)   # a valid configuration


def test_ddpg_report_humanoid_experiment_is_table_4_and_its_large_variant():
    specs = {spec.name: spec for spec in get_experiment("ddpg-report-humanoid").runs}
    assert set(specs) == set(REPORT_DDPG_HUMANOID_TABLES)
    for name, table in REPORT_DDPG_HUMANOID_TABLES.items():
        spec = specs[name]
        assert spec.env_id == "Humanoid-v5" and spec.overrides["exploration"] == "gaussian"
        assert spec.steps == report_steps(table), name
        for field, value in report_overrides(table).items():
            assert spec.overrides[field] == value, (name, field)

"""The two test processes' schedule (conftest.py): the modules that start local Ray clusters run in one process, one
after the other; every other test module and every chapter stays a scope of its own, as ``--dist loadscope`` makes
it."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _root_conftest():
    spec = importlib.util.spec_from_file_location("root_conftest", ROOT / "conftest.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_ray_modules_share_one_scope_and_the_rest_keep_their_own(pytestconfig, monkeypatch):
    conftest = _root_conftest()
    monkeypatch.setattr(pytestconfig.option, "dist", "loadscope")
    monkeypatch.setattr(pytestconfig.option, "tx", ["2*popen"], raising=False)  # what -n 2 becomes
    scheduling = conftest.pytest_xdist_make_scheduler(pytestconfig, None)
    scope = scheduling._split_scope
    assert scope("tests/test_cluster.py::test_a") == scope("tests/test_cluster_nodes.py::test_b[x]") == "ray"
    assert scope("tests/test_cli.py::test_render_writes_a_gif") == "tests/test_cli.py"
    assert scope("chapters/02_dqn.md::Cell 3") == "chapters/02_dqn.md"
    assert all((ROOT / path).is_file() for path in conftest.ONE_AT_A_TIME)  # a renamed module would escape it
    monkeypatch.setattr(pytestconfig.option, "dist", "load")  # another --dist: xdist's own scheduler
    assert conftest.pytest_xdist_make_scheduler(pytestconfig, None) is None

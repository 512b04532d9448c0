"""The crossway command run as a user would: a subprocess with tiny budgets."""

import json
import subprocess
import sys

import pytest


def crossway(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "crossway", *args], capture_output=True, text=True,
                          timeout=timeout)


def test_help_lists_commands():
    result = crossway("--help")
    assert result.returncode == 0
    for command in ("render", "bench"):
        assert command in result.stdout


def test_bench_sim_prints_one_json_object():
    result = crossway("bench", "sim", "--scenario", "easy", "--seconds", "1", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["scenario"] == "easy"
    assert report["lanes"] == 3
    assert 2.0 < report["agents"] <= 3.0  # lanes stay busy
    assert report["agent_steps_per_s"] > 0
    assert report["views"] is True


@pytest.mark.parametrize("args, message", [
    (["bench", "sim", "--seconds", "0"], "--seconds"),
    (["bench", "sim", "--scenario", "nowhere.toml", "--seconds", "1"], "not a built-in scenario"),
])
def test_bench_bad_input(args, message):
    result = crossway(*args)
    assert result.returncode == 2
    assert message in result.stderr
    assert "Traceback" not in result.stderr

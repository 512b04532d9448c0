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


def test_every_help_says_defaults_once_and_never_none():
    """Every subcommand's --help, as argparse prints it: "(default: X)" where a default says
    something, and not after a required option, an on/off flag, a default of None or "", or a help
    text that already names its default."""
    import argparse

    from crossway.cli import build_parser

    def parsers(parser, name):
        yield name, parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub, child in action.choices.items():
                    yield from parsers(child, f"{name} {sub}")

    shown = 0
    for name, parser in parsers(build_parser(), "crossway"):
        text = " ".join(parser.format_help().split())  # argparse wraps lines anywhere
        assert "(default: None)" not in text, name
        assert "(default: False)" not in text and "(default: )" not in text, name
        shown += text.count("(default: ")
        for action in parser._actions:
            words = " ".join((action.help or "").split())
            if words and "default" in words.lower():
                assert f"{words} (default: " not in text, (name, action.option_strings)
    assert shown > 100  # the defaults that say something are still there
    help_of = dict(parsers(build_parser(), "crossway"))
    train = " ".join(help_of["crossway train"].format_help().split())
    assert "the default step (0.001)" in train  # a help that names its default fills it in
    table1 = " ".join(help_of["crossway evaluate table1"].format_help().split())
    assert "(the paper: 3000) (default: 3000)" in table1


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



def test_bench_policy_times_an_ensemble_as_driven_and_joined(tmp_path):
    import torch
    from dataclasses import asdict

    from algo.policy import Policy, PolicyConfig

    members = [Policy(PolicyConfig()) for _ in range(2)]
    path = tmp_path / "ensemble.pt"
    torch.save({"members": [{"policy": m.state_dict(), "policy_config": asdict(m.config)} for m in members]}, path)
    result = crossway("bench", "policy", "--checkpoint", str(path), "--seconds", "0.5", "--cars", "3", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["members"] == 2 and report["network"] == [32, 32, 256]
    assert report["as_driven_calls_per_s"] > 0 and report["joined_calls_per_s"] > 0
    assert report["as_driven_ms_per_car"] == pytest.approx(1000.0 / report["as_driven_calls_per_s"] / 3, rel=0.01)
    assert report["platform"]["torch_cpu_capability"] == torch.backends.cpu.get_cpu_capability()  # what ran
    assert report["views"] == "simulator" and report["scenario"] == "hard"
    assert 0 < report["distinct_patch_fraction"] < 0.5  # a simulator's views are mostly flat
    assert report["full_product_calls_per_s"] > 0 and report["speedup_over_full_product"] > 0
    noise = crossway("bench", "policy", "--checkpoint", str(path), "--seconds", "0.5", "--cars", "2", "--views",
                     "noise", "--json")
    assert noise.returncode == 0, noise.stderr
    assert json.loads(noise.stdout)["distinct_patch_fraction"] == 1.0
    refused = crossway("bench", "policy", "--checkpoint", str(tmp_path / "missing.pt"))
    assert refused.returncode == 2
    assert "no checkpoint file" in refused.stderr and "Traceback" not in refused.stderr
    too_many = crossway("bench", "policy", "--checkpoint", str(path), "--cars", "9")
    assert too_many.returncode == 2
    assert "hard has only 8 lanes" in too_many.stderr and "Traceback" not in too_many.stderr

def test_bench_actor_and_learner_print_json():
    actor = crossway("bench", "actor", "--scenario", "easy", "--seconds", "2", "--update-interval", "5", "--json",
                     timeout=180)
    assert actor.returncode == 0, actor.stderr
    report = json.loads(actor.stdout)
    assert report["agent_steps_per_s"] > 0 and report["bare_forward_backward_samples_per_s"] > 0
    assert report["platform"]["torch"] == report["torch"]
    assert report["ratio_to_bare"] == pytest.approx(
        report["agent_steps_per_s"] / report["bare_forward_backward_samples_per_s"], rel=0.01)
    assert report["peak_rss_bytes"] > 0
    learner = crossway("bench", "learner", "--seconds", "3", "--json", timeout=180)
    assert learner.returncode == 0, learner.stderr
    report = json.loads(learner.stdout)
    assert report["pushes_applied_per_s"] > 0
    assert report["rejected"] == 0
    assert report["rss_max_bytes"] >= report["rss_start_bytes"] > 0

"""simcore: the intersection simulator, its semantic views and a PettingZoo environment.

No torch here. Entry points:

- ``make_env(scenario, **options)``: a PettingZoo ``ParallelEnv`` (``simcore.env``);
- ``Simulator(scenario, SimConfig(...), seed)``: the batch path the actors use;
- ``load_scenario(name_or_path)``: a validated ``ScenarioSpec`` (built-in: easy, medium, hard).
"""

from simcore.scenario import BUILTIN_SCENARIOS, ScenarioError, ScenarioSpec, load_scenario
from simcore.simulator import SimConfig, Simulator, StepResult


def make_env(scenario: str | ScenarioSpec = "easy", **options):
    """A PettingZoo ``ParallelEnv`` of ``scenario`` (a built-in name, a TOML path or a spec).

    Options: ``max_cycles`` (steps before every agent is truncated, default 1000),
    ``render_mode`` (None or "rgb_array") and any ``SimConfig`` field (``delay_max_s``,
    ``time_limit_s``, ``lanes``, ``observe``, ...). Unknown options raise ``TypeError``.
    """
    from simcore.env import IntersectionParallelEnv

    return IntersectionParallelEnv(scenario, **options)


__all__ = [
    "BUILTIN_SCENARIOS", "ScenarioError", "ScenarioSpec", "SimConfig", "Simulator", "StepResult",
    "load_scenario", "make_env",
]

"""Slider: a block on a spring (``slider.xml``; its MuJoCo plant in ``physics.py``) that tracks a
reference position jumping at random times: the ``track`` task (``task.py``), the analytic
spring-mass-damper as the MPC's predictor (``model.py``, deliberately mismatched), and the system the
loop plays (``system.py``: a Gauss-Newton MPC with the reference as a parameter and a time-varying
LQR along each plan). ``trigger.py`` adds a policy kind, ``driftage:X:T``.

An example of a task that lives outside etmpc: this package announces itself with an ``etmpc.tasks``
entry point (``slider = "etmpc_slider"``), and etmpc's registry reads the names below.
"""

from pathlib import Path

# Its tasks, the default first: what etmpc lists without loading MuJoCo, dm-control or CasADi (the
# first two pick their OpenGL backend on import). SYSTEMS and SUITE load the modules when first asked.
TASKS = ("track",)
# The seed of each task's stored test set (data/<task>_testset.npz: etmpc testset --task slider --seed SEED).
TEST_SET_SEEDS = {"track": 20261201}
# The folder of the stored test sets and references (package data).
DATA = Path(__file__).resolve().with_name("data")


def __getattr__(name: str):
    if name == "SYSTEMS":  # task -> the System class the loop plays
        from etmpc_slider.system import SliderSystem

        return {"track": SliderSystem}
    if name == "SUITE":  # the dm-control task factories, as a dm_control.suite domain has them
        from etmpc_slider.task import SUITE

        return SUITE
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

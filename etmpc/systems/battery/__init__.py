"""Battery storage trading: a plain-numpy plant under dm-control (``task.py``), prices, production and
forecasts drawn by ``market.py`` from the numbers in ``parameters.py``, the economic MPC as a linear
program (``mpc.py``, checked against ``reference.py``), and the system the loop plays (``system.py``).
"""

# Its tasks, the default first: what etmpc.systems lists without loading MuJoCo or dm-control (which
# pick their OpenGL backend on import). SYSTEMS and SUITE load the domain's modules when first asked.
TASKS = ("trading",)


def __getattr__(name: str):
    if name == "SYSTEMS":  # task -> the System class the loop plays
        from etmpc.systems.battery.system import BatterySystem

        return {"trading": BatterySystem}
    if name == "SUITE":  # the dm-control task factories, as a dm_control.suite domain has them
        from etmpc.systems.battery.task import SUITE

        return SUITE
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

"""Make the slider known to etmpc when this package is not installed (its entry point then does it).

Run from a source checkout as ``python -m pytest examples/etmpc_slider/tests``: the package's folder is
put on ``sys.path`` and the domain registered by hand, as an installed plugin's entry point would.
"""

import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

HERE = Path(__file__).resolve().parents[1]
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import etmpc.systems as systems  # noqa: E402

if "slider" not in systems.domains():  # not installed: the cached registry learns it by hand
    import etmpc_slider  # noqa: E402

    systems.domains()["slider"] = etmpc_slider

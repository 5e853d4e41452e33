"""etmpc: a benchmark for event-triggered model predictive control.

An MPC makes plans, an LQR corrects prediction errors while a plan is kept, and a recomputation
policy decides when to re-plan. See README.md.
"""

import os

# Headless rendering by default (dm-control chooses its OpenGL backend when first imported);
# set MUJOCO_GL yourself to choose another backend.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"

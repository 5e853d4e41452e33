"""The built wheel ships the model and test set inside `etmpc` and no bare `tasks`/`models` module."""

import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_wheel_contents(tmp_path):
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(tmp_path), str(ROOT)],
                   check=True, capture_output=True)
    (wheel,) = tmp_path.glob("etmpc-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    top_level = {name.split("/")[0] for name in names}
    assert top_level == {"etmpc", f"{wheel.name.split('-')[0]}-{wheel.name.split('-')[1]}.dist-info"}
    assert "etmpc/_data/models/cart_pendulum.xml" in names
    assert "etmpc/_data/tasks/cart_pendulum/balance_testset.npz" in names
    assert "etmpc/_data/tasks/cart_pendulum/balance_testset.npz.sha256" in names
    assert "etmpc/_data/tasks/battery/trading_testset.npz" in names
    assert "etmpc/battery/system.py" in names

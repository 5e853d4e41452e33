"""The paper's Figure 3: the mean objective per recomputation policy, from `etmpc evaluate --json`
documents of one task (error bars: std over repeats; a training run's seeds as one learned bar).

    etmpc evaluate cart_pendulum --policy always --policy every:3 --json eval.json
    python scripts/figure_bars.py eval.json [learned.json ...] [--out fig3.png] [--no-group]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from etmpc.common.errors import EtmpcError
from etmpc.views.figures import write_policy_bars_png


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line on stderr, exit code 2
        self.exit(2, f"{self.prog}: error: {message}\n")


def load(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise EtmpcError(f"{path} not found") from None
    except IsADirectoryError:
        raise EtmpcError(f"{path} is a directory, not a file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise EtmpcError(f"cannot read {path}: {exc}") from None
    except json.JSONDecodeError as exc:
        raise EtmpcError(f"{path} is not valid JSON ({exc})") from None


def main(argv: list[str] | None = None) -> int:
    parser = _Parser(description=__doc__.splitlines()[0])
    parser.add_argument("evaluations", nargs="+", type=Path, metavar="EVAL.json", help="etmpc evaluate --json output")
    parser.add_argument("--out", type=Path, default=None, metavar="PNG", help="default results/figure3_<task>.png")
    parser.add_argument("--no-group", action="store_true", help="one bar per learned policy file, not one per training run")
    args = parser.parse_args(argv)

    try:
        docs = [load(path) for path in args.evaluations]
        domain = docs[0].get("domain") if isinstance(docs[0], dict) else None
        out = args.out or Path("results") / f"figure3_{domain}.png"
        if out.exists() and out.is_dir():
            raise EtmpcError(f"--out {out} is a directory")
        write_policy_bars_png(out, docs, group_learned=not args.no_group, sources=[str(p) for p in args.evaluations])
    except EtmpcError as exc:
        parser.error(str(exc))
    except OSError as exc:
        parser.error(f"cannot write {out}: {exc.strerror or exc}")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

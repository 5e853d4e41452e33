"""Regenerate a stored test set from its seed, bit for bit, or check that the stored one matches.

    python scripts/make_testset.py cart_pendulum            # (re)write tasks/cart_pendulum/...
    python scripts/make_testset.py cart_pendulum --check    # exit 1 unless the stored bytes match
"""

from __future__ import annotations

import argparse
import hashlib
import sys

from etmpc.evaluation import testsets as testset
from etmpc.systems import make_system, names

SEEDS = {"cart_pendulum": 20210601, "battery": 20210602}  # one fixed seed per system's test set
EPISODES = 100


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("domain", choices=names())
    parser.add_argument("--check", action="store_true", help="compare with the stored file instead of writing")
    args = parser.parse_args(argv)

    system = make_system(args.domain)
    path = testset.default_path(system.domain, system.task)
    arrays, meta = testset.generate(system, SEEDS[args.domain], EPISODES)
    data = testset.encode(arrays, meta)
    digest = hashlib.sha256(data).hexdigest()
    if args.check:
        same = path.is_file() and path.read_bytes() == data
        print(f"{path}: {'identical' if same else 'DIFFERS'} (regenerated sha256 {digest})")
        return 0 if same else 1
    testset.write(path, arrays, meta)
    print(f"wrote {path} ({len(data)} bytes, sha256 {digest})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

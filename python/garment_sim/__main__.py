"""``python -m garment_sim sweep SWEEP.yaml --out DIR [--scheduler ADDR] [--workers N]``."""

import sys

from .sweep import main

if __name__ == "__main__":
    args = sys.argv[1:]
    if not args or args[0] != "sweep":
        print("usage: python -m garment_sim sweep SWEEP.yaml --out DIR "
              "[--scheduler tcp://HOST:8786] [--workers N]", file=sys.stderr)
        sys.exit(2)
    sys.exit(main(args[1:]))

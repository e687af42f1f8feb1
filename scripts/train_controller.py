#!/usr/bin/env python
"""Train a controller: a thin wrapper over ``fir-gym train`` (same arguments)."""

import sys

from fir_gym.cli import main

if __name__ == "__main__":
    raise SystemExit(main(["train", *sys.argv[1:]]))

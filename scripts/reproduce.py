#!/usr/bin/env python
"""Reproduce the papers' experiments: a thin wrapper over ``fir-gym reproduce``."""

import sys

from fir_gym.cli import main

if __name__ == "__main__":
    raise SystemExit(main(["reproduce", *sys.argv[1:]]))

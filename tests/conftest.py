"""Test-session settings: headless MuJoCo rendering (EGL) unless the caller chose a backend."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

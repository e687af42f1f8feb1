"""fir-gym: Gymnasium plants from five state-estimation papers, with pluggable estimators.

``import fir_gym`` registers every environment id listed in :data:`ENV_IDS`.
"""

from __future__ import annotations

from ._registration import ENV_IDS, VECTOR_ENV_IDS, register_envs

__version__ = "0.1.0"

register_envs()

__all__ = ["ENV_IDS", "VECTOR_ENV_IDS", "__version__", "register_envs"]

"""fir-gym: Gymnasium plants from five state-estimation papers, with pluggable estimators.

``import fir_gym`` registers every environment id listed in :data:`ENV_IDS`;
:func:`register_plant` registers a plant of the user's own under the user's own id.
"""

from __future__ import annotations

from ._registration import ENV_IDS, VECTOR_ENV_IDS, register_envs, register_plant

__version__ = "0.1.0"

register_envs()

__all__ = ["ENV_IDS", "VECTOR_ENV_IDS", "__version__", "register_envs", "register_plant"]

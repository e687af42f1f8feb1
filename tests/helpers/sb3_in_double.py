"""An SB3 (or sb3-contrib) policy in float64, for the tests that compare our networks with it
to round-off."""

from __future__ import annotations

from typing import Any


def in_double(policy: Any) -> Any:
    """``policy`` made double. SB3's ``preprocess_obs`` casts a Box observation to float32
    before the features extractor (a flatten): the tests' observations are float32 numbers, so
    the extractor casting back to float64 leaves the same function, in float64."""
    import torch

    policy.features_extractor.forward = lambda obs: torch.flatten(obs, 1).double()
    return policy.double()

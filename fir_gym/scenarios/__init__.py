"""The papers' experiments, one module per paper.

Each report puts the paper's numbers beside ours.
"""

#: The paper scenarios ``fir-gym reproduce`` runs, in order (modules of this package,
#: each with ``run(seed=0, quick=False) -> Report``).
SCENARIOS: tuple[str, ...] = ("paper000", "paper001", "paper002", "paper003", "paper004", "sweeps")

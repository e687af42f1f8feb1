"""The papers' experiments, one module per paper.

Each report puts the paper's numbers beside ours.
"""

"""The papers' experiments, one module per paper, each returning a report with the paper's numbers beside ours."""

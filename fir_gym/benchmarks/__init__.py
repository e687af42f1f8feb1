"""Speed benchmarks: each module measures ratios against a reference timed in the same run."""

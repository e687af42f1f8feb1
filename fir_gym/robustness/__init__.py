"""``fir-gym benchmark-robustness``: which estimator belongs in a closed loop when the model
is wrong and the sensor misbehaves (docs/robustness.md).

:mod:`.plan` says what runs, :mod:`.closed_loop` plays batches of episodes under a
condition, :mod:`.lqg_grid` and :mod:`.learned_grid` are the two grids' tasks,
:mod:`.summaries`, :mod:`.recovery` and :mod:`.tables` turn episodes into numbers, and
:mod:`.benchmark` runs it all on the serial, joblib or Dask runner and writes the report.
"""

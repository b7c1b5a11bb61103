"""Results in three parts: :mod:`.run` plays (policy, task, seed) episodes into tidy rows (one per
episode, CSV); :mod:`.stats` computes on rows (mean intervals, paired and geometric comparisons,
the normalized score, the IQM, noise floors); :mod:`.report` turns rows and statistics into
Markdown tables and figures (:mod:`.cells` formats their cells). ``lawn evaluate``, ``lawn
benchmark`` (the paper protocol, the learned protocol, the suite, the fleet sizes) and the docs'
tables are compositions of the three;
:func:`.api.compare` is their front door from Python (typed episode results and paired statistics)."""

"""The results pipeline, one record from spec to page: :mod:`.episode` holds the records
(:class:`~.episode.EpisodeSpec` in, :class:`~.episode.EpisodeResult` out) and their CSV; :mod:`.run`
plays specs into results (the worker pool, the reference rows); :mod:`.stats` reduces results
(mean intervals, paired and geometric comparisons, the two test ranges, the normalized score and
its IQM); :mod:`.report` turns statistics into Markdown tables and figures (:mod:`.cells` formats
their cells); :mod:`.protocols` declares what ``lawn benchmark`` plays and writes (the paper protocol,
the learned protocol, the suite, the fleet sizes). :func:`.api.compare` is the front door from
Python."""

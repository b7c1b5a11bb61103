"""The results pipeline, one record from spec to page: :mod:`.episode` holds the records
(:class:`~.episode.EpisodeSpec` in, :class:`~.episode.EpisodeResult` out) and their CSV; :mod:`.run`
plays specs into results (the worker pool, the reference rows); :mod:`.rows` reduces results per
table row (:func:`~.rows.reduce`) with the statistics of :mod:`.stats` (mean intervals, paired and
geometric comparisons, the two test ranges, the normalized score and its IQM); :mod:`.report` turns
the rows' statistics into Markdown tables and figures (:mod:`.cells` formats their cells);
:mod:`.protocols` declares what ``lawn benchmark`` plays and which tables it makes, and plays any
protocol one way (:func:`~.protocols.execute`); :mod:`.digests` keeps the README rows' episodes.
The seed ranges every package shares are in :mod:`.seeds`; the worker pool in :mod:`.pool`;
parameter sweeps in :mod:`.sweep`; one episode shown (``lawn render``, ``lawn demo``) in
:mod:`.render`; the commit that made a result in :mod:`.provenance`. :func:`.api.compare` is the
front door from Python."""

"""Training, evaluation, benchmarks, sweeps, figures and the ``lawn`` command line."""

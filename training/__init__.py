"""Learning: the run spec and the recipes (:mod:`.spec`, :mod:`.recipes`), ``lawn train``
(:mod:`.train`: SB3 in :mod:`.sb3`, behaviour cloning and DAgger in :mod:`.bc` and :mod:`.fleet`,
distillation in :mod:`.distil`), the periodic validation that selects a model on seeds disjoint
from the test seeds (:mod:`.validation`, :mod:`.callbacks`), expert datasets (:mod:`.datasets`)
and the shipped agents' evaluation and export (:mod:`.zoo`)."""

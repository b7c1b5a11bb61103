"""The paper's reproduction and the generated pages: the experiments behind every figure and claim
(:mod:`.experiments`, ``lawn figures``), the docs' generated blocks and the one command that
refreshes them (:mod:`.pages`), the task suite's pages (:mod:`.leaderboard`) and docs/LEARNED.md's
zoo blocks (:mod:`.learned`)."""

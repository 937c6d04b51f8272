"""Planners on top of a policy: the one-step rollout (omniscient, :mod:`.rollout`) and the
decentralized rollout on each robot's own ego-graph (:mod:`.local_rollout`)."""

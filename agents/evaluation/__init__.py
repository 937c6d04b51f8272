"""Evaluation over fixed, paired seeds; paired comparisons; the paper's published numbers."""

from marl_cover.agents.evaluation.episodes import EpisodeResult, Summary, evaluate, run_episode

__all__ = ["EpisodeResult", "Summary", "evaluate", "run_episode"]

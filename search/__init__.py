"""Inference-time search (no Ray): MCTS with the learned policy and value."""

from eosp.search.mcts import SearchParams, SearchStats, search, solve  # noqa: F401

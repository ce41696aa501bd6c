"""The stair-climbing env: observation, rewards, endings, curriculum, auto-reset (uses sim)."""

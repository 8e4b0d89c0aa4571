"""trustroute/core."""

"""policies/belief."""

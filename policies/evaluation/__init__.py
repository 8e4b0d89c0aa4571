"""policies/evaluation."""

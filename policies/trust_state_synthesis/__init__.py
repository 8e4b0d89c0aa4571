"""policies/trust_state_synthesis."""

"""harness: running things.

Owns the libsumo episode runner, incident injection, takeover actuation, the
study runner (local pool / Dask), the CLI and Rerun logging. Must not decide
routes itself: every route choice comes from a policy in `policies/`.
"""

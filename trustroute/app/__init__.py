"""The application layer: the one place where a run is put together.

The defaults every door reads are trustroute/core/defaults.py (import-free, so the API names
them in its signatures). Every entry point (the Python API, each CLI command, the gymnasium
environment, a study's context, the live station and its replay, the fitting command's policy
check) assembles a run through these modules instead of its own copy:

    inputs.py    town, driver model, population and spec by packaged name or path, the defaults
                 filled in; a packaged spec knows its town (`city5`, `csomor5`)
    problem.py   the compiled Problem (population lifting, the case) built once and passed down,
                 and the initial-trust check
    policy.py    `policy_for(problem, "free" | "aware" | "robust" | "bayes" | path, settings)`
    nets.py      `net_for(town)`: the SUMO net a town drives (built, or the imported net)
    drivers.py   the synthetic driver of an episode, a population's drawn type, episode ids
    synthesis.py synthesis and exact evaluation with their settings objects, the trust-free baseline
    spec_check.py, peers.py, towns.py, populations.py
                 what `spec check`, `peer`, `model`/`net`/`town` and `population`/`fit` assemble
    engines.py   the engine registry (`model`, `sumo`, `live`): each member declares what it can do
    runs.py      whole runs for the API and the CLI: one episode, the packaged policy check
    planning.py  `trustroute plan`'s run: the participants (a pilot's fit), the simulated studies,
                 their power, the power curve and the payload

The package is spread over three layers (tests/test_architecture.py, docs/internals.md): the
assembly modules sit just above `policies`, so the simulation, study, live and analysis layers may
call them; `engines.py` sits with `harness.simulation` (its members run that layer's episodes); the
package itself, `runs.py` and `planning.py` sit above `analysis`, below the API and the CLI.
"""

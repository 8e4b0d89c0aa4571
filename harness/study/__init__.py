"""harness.study: simulated within-subject studies at scale.

config        the TOML study config (frozen dataclass, one-line errors)
latin_square  the counterbalanced order of conditions per participant (Williams design)
plan          the episodes of a study with their seeds and drivers (deterministic)
parts         one atomic Parquet part per episode; corruption check, failure records
resume        where a study is resumed: the directory checked as this study's, finished parts
              found, damaged ones moved aside
runner        local process pool or Dask, through one code path
manifest      the consolidated dataset and its manifest (hashes, versions, seeds, git revision)
expected      exact values and synthesized bounds of the study's policies (beside the simulated rates)
examples/     example study configs (paper.toml, paper_strict.toml, population_model.toml,
              held_out_types.toml)
"""

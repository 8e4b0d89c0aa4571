"""`with_options`: a settings object with some fields given by keyword, checked again."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from trustroute.core.settings import with_options


@dataclass(frozen=True)
class Limits:
    horizon: int | None = None
    tau: float = 1e-3

    def __post_init__(self) -> None:
        if not self.tau > 0:
            raise ValueError("tau must be positive")


def test_the_named_fields_replace_the_settings_ones():
    base = Limits(horizon=4)
    assert with_options(base, Limits(), {"tau": 0.5}, "synthesize") == Limits(horizon=4, tau=0.5)
    assert with_options(base, Limits(), {}, "synthesize") is base


def test_an_unknown_name_is_a_type_error_naming_the_fields():
    with pytest.raises(TypeError, match=r"synthesize\(\) got an unexpected keyword argument 'horizn'; "
                                        r"it takes the fields of Limits: horizon, tau"):
        with_options(None, Limits(), {"horizn": 3}, "synthesize")


def test_a_replaced_field_is_checked_again():
    with pytest.raises(ValueError, match="tau must be positive"):
        with_options(None, Limits(), {"tau": 0.0}, "synthesize")


def test_no_settings_are_the_default_ones():
    assert with_options(None, Limits(horizon=2), {"tau": 0.5}, "synthesize") == Limits(horizon=2, tau=0.5)


@dataclass(frozen=True)
class Other:
    horizon: int = 1


@pytest.mark.parametrize("settings", [Other(), {"horizon": 6}])
def test_settings_of_another_class_are_a_type_error_naming_the_class(settings):
    with pytest.raises(TypeError, match=r"synthesize\(\) got settings of type (Other|dict); pass a "
                                        r"tests\.core\.test_settings\.Limits, or its fields by keyword "
                                        r"\(horizon, tau\)"):
        with_options(settings, Limits(), {}, "synthesize")


def test_every_door_refuses_settings_of_another_class():
    import gymnasium

    import trustroute
    from trustroute.app.runs import EpisodeSettings
    from trustroute.app.synthesis import EvaluationSettings, SynthesisSettings
    from trustroute.harness.simulation.gym_env import ENV_ID

    doors = [(lambda: trustroute.synthesize("phi1", settings=EvaluationSettings()), "SynthesisSettings"),
             (lambda: trustroute.run_episode("phi1", settings=SynthesisSettings()), "EpisodeSettings"),
             (lambda: trustroute.evaluate("phi1", settings=SynthesisSettings()), "EvaluationSettings"),
             (lambda: gymnasium.make(ENV_ID, settings=EpisodeSettings()), "EnvSettings"),
             (lambda: trustroute.synthesize("phi1", settings={"horizon": 6}), "SynthesisSettings")]
    for call, expected in doors:
        refused = rf"got settings of type \w+; pass a [\w.]+\.{expected}, or its fields"
        with pytest.raises(TypeError, match=refused):
            call()

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
    assert with_options(base, {"tau": 0.5}, "synthesize") == Limits(horizon=4, tau=0.5)
    assert with_options(base, {}, "synthesize") is base


def test_an_unknown_name_is_a_type_error_naming_the_fields():
    with pytest.raises(TypeError, match=r"synthesize\(\) got an unexpected keyword argument 'horizn'; "
                                        r"it takes the fields of Limits: horizon, tau"):
        with_options(Limits(), {"horizn": 3}, "synthesize")


def test_a_replaced_field_is_checked_again():
    with pytest.raises(ValueError, match="tau must be positive"):
        with_options(Limits(), {"tau": 0.0}, "synthesize")

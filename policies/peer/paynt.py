"""PAYNT's finite-state controller synthesis on the exported product (paynt, the optional `[peer]` extra).

PAYNT (GPL-3.0, an optional peer, never imported by the package's own solvers) searches
finite-state controllers (FSCs) of the product POMDP of policies/peer/product_pomdp.py for
Pmax=? [F "goal"] by abstraction refinement, with k = 1, 2, ... memory nodes per observation
until the time limit. The value it reports is the value of the best controller found: a LOWER
bound of Pr_max, never an upper one. A k-memory FSC sees the current observation (road, last
(h, e), step counter) and its k memory nodes, not the whole history, so its optimum can lie
below the optimum over history-dependent policies (which ours and Storm's unfolding bracket);
the bound is comparable with our L, not with U. PAYNT model-checks each controller with Storm's
iterative solvers at `PRECISION`, so the value is sound up to that solver precision.

SAYNT (PAYNT with Storm's belief exploration) is not run: paynt 0.5.0 builds its Storm options
with stormpy.pomdp.BeliefExplorationModelCheckerOptionsDouble, which stormpy 2.0.0 (the version
paynt pins) does not provide (`saynt_available` checks for it).
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.policies.peer.product_pomdp import ExplicitProduct, no_goal_note

INSTALL_HINT = "install the optional peer extra: pip install 'trustroute[peer]' (paynt==0.5.0, GPL-3.0)"
PRECISION = 1e-6                 # PAYNT's model-checking precision (its default is 1e-4)
MAX_PRODUCT_STATES = 200_000     # beyond, PAYNT's colored MDP (states × memory) does not fit
NO_GOAL_NOTE = no_goal_note("PAYNT")


def paynt_available() -> bool:
    return importlib.util.find_spec("paynt") is not None


def require_paynt(source: str = "paynt") -> None:
    """InputError with the install hint when paynt is absent."""
    if not paynt_available():
        raise InputError(source, "", "PAYNT (paynt) is not installed", INSTALL_HINT)


def saynt_available() -> bool:
    """Whether the installed stormpy has the belief-exploration options SAYNT builds."""
    if not paynt_available():
        return False
    import stormpy.pomdp
    return hasattr(stormpy.pomdp, "BeliefExplorationModelCheckerOptionsDouble")


@dataclass(frozen=True)
class PayntResult:
    """`value` is the best controller's value (None when none was found in time): a lower bound."""

    value: float | None
    found: bool
    seconds: float
    build_seconds: float
    memory_nodes: int            # the largest k PAYNT reached (memory nodes per observation)
    states: int
    time_limit: float
    precision: float = PRECISION
    bound: str = "lower"
    note: str = ""   # why PAYNT was not run, when the answer needs no solver

    @property
    def lower(self) -> float:
        """The lower bound it gives: the controller's value, or 0 when none was found."""
        return self.value if self.value is not None else 0.0

    def to_dict(self) -> dict:
        return {"value": self.value, "found": self.found, "lower": self.lower, "bound": self.bound,
                "seconds": self.seconds, "build_seconds": self.build_seconds,
                "memory_nodes": self.memory_nodes, "states": self.states,
                "time_limit": self.time_limit, "precision": self.precision, "note": self.note}


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """Storm's C++ parsers print to file descriptors 1 and 2 while PAYNT tries its input formats in
    turn, and PAYNT logs through `logging`: both are silenced for the run and restored after."""
    logger = logging.getLogger("paynt")
    level = logger.level
    logger.setLevel(logging.ERROR)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
            yield
    finally:
        for fd, copy in ((1, saved[0]), (2, saved[1])):
            os.dup2(copy, fd)
            os.close(copy)
        logger.setLevel(level)


def run_paynt(product: ExplicitProduct, time_limit: float = 10.0,
              max_states: int = MAX_PRODUCT_STATES) -> PayntResult:
    """PAYNT's FSC synthesis (abstraction refinement, memory 1, 2, ...) for `time_limit` seconds;
    the value 0 with a note, without PAYNT, when no reachable state satisfies the spec."""
    require_paynt()
    if not product.goal.any():
        # the answer is known whatever the product's size: PAYNT is not run, so --max-states has
        # nothing to refuse
        return PayntResult(value=0.0, found=True, seconds=0.0, build_seconds=0.0, memory_nodes=0,
                           states=product.n_states, time_limit=float(time_limit), note=NO_GOAL_NOTE)
    if product.n_states > max_states:
        raise InputError("trustroute peer paynt", "", f"the product POMDP has {product.n_states} states, "
                         f"more than PAYNT is run on here ({max_states})",
                         "use a smaller town or horizon, or raise --max-states")
    import paynt.api
    import paynt.parser.sketch
    import paynt.utils.timer

    started = time.perf_counter()
    paynt.utils.timer.GlobalTimer.start(time_limit)
    try:
        with tempfile.TemporaryDirectory(prefix="trustroute-paynt-") as folder, _quiet():
            sketch, props = Path(folder) / "sketch.drn", Path(folder) / "sketch.props"
            sketch.write_text(product.to_drn())
            props.write_text(product.query + "\n")
            factory, task = paynt.parser.sketch.Sketch.load_sketch(
                str(sketch), str(props), precision=PRECISION, task_kwargs={"memory_size": 1})
            build_seconds = time.perf_counter() - started
            synthesizer = paynt.api.get_synthesizer(factory, task, "ar", fsc_synthesis=True)
            result = synthesizer.run()
    except (AssertionError, RuntimeError, ValueError, MemoryError) as exc:
        raise InputError("trustroute peer paynt", "", f"PAYNT could not solve the product "
                         f"({type(exc).__name__}: {exc})", "use a smaller town or horizon") from exc
    value = float(result.value) if result.success and result.value is not None else None
    return PayntResult(value=value, found=value is not None, seconds=time.perf_counter() - started,
                       build_seconds=build_seconds, memory_nodes=int(synthesizer.current_memory_size),
                       states=product.n_states, time_limit=float(time_limit))

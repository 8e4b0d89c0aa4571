"""The labeller reads a belief the same way in a batch of any shape (policies/logic/labelling.py)."""

from __future__ import annotations

import numpy as np

from trustroute.networks.town import load_town
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.labelling import SMALL_BATCH, atom_values
from trustroute.policies.logic.spec import spec_from_text


def test_a_belief_on_its_threshold_reads_the_same_label_in_every_batch():
    """For random beliefs b and 0/1 coefficient vectors, the offset is set to c·b as the labeller
    sums it; the label of b (strictly false there) and its margins must not change when b is read
    alone or among 1-300 other rows (a BLAS product sums a row differently by batch size)."""
    town = load_town()
    rng = np.random.default_rng(20261202)
    checked = 0
    for _ in range(40):
        belief = rng.dirichlet(np.ones(7) * rng.uniform(0.2, 3))
        coeffs = rng.integers(0, 2, size=7).astype(float)
        coeffs[int(rng.integers(7))] = 1.0
        offset = float(atom_values(belief[None, :], coeffs[:, None])[0, 0])
        text = (f'name = "t"\nstart = "{town.states[0]}"\nformula = "F high"\n[states]\n'
                f"[beliefs.high]\ncoeffs = {coeffs.tolist()}\noffset = {offset!r}\n")
        labeller = compile_spec(spec_from_text(text, "<t>", town), town).labeller
        x = np.zeros(1, dtype=np.int64)
        alone = labeller.valuations(x, belief[None, :])[0]
        truth_alone, either_alone = labeller.belief_margins(belief[None, :])
        assert not truth_alone[0, 0] and either_alone[0, 0]
        for size in (1, 2, 3, 7, 8, 31, 64, 300):
            batch = rng.dirichlet(np.ones(7), size=size)
            where = int(rng.integers(size))
            batch[where] = belief
            read = labeller.valuations(np.zeros(size, dtype=np.int64), batch)[where]
            truth, either = labeller.belief_margins(batch)
            assert np.array_equal(read, alone), (size, offset)
            assert truth[where, 0] == truth_alone[0, 0] and either[where, 0] == either_alone[0, 0]
            checked += 1
    assert checked == 40 * 8


def test_atom_values_sum_in_trust_level_order_at_every_batch_size():
    """Both of atom_values' paths (one accumulate for small batches, a loop over the levels for
    large ones) give c·b summed level after level, as Python floats add it, bit for bit."""
    rng = np.random.default_rng(20261205)
    for rows in (1, 2, SMALL_BATCH, SMALL_BATCH + 1, 300):
        levels, atoms = int(rng.integers(1, 22)), int(rng.integers(1, 4))
        beliefs = rng.dirichlet(np.ones(levels), size=rows) * rng.uniform(0.5, 2.0)
        coeffs = rng.normal(size=(levels, atoms)) * 10.0 ** rng.uniform(-3, 3, size=(levels, 1))
        values = atom_values(beliefs, coeffs)
        assert values.shape == (rows, atoms) and values.flags.c_contiguous
        for i in range(rows):
            for j in range(atoms):
                total = float(beliefs[i, 0]) * float(coeffs[0, j])
                for level in range(1, levels):
                    total += float(beliefs[i, level]) * float(coeffs[level, j])
                assert values[i, j] == total, (rows, i, j)

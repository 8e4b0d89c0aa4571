"""The suffix cells and the atoms' status on their images, against their definitions written out
word by word and vertex by vertex: the cells built a level at a time must equal, bit for bit, the
corners f_w(e_i) computed one word and one symbol at a time, and each word's successor must be its
last k symbols."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from tests.policies.evaluation.test_random_models import random_driver
from trustroute.participants.driver_model import DriverModel
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population
from trustroute.policies.belief.driver_types import lift_population
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.synthesis.belief_cells import (
    LABEL_TOLERANCE,
    image_label_status,
    observation_symbols,
    reachable_states,
    suffix_cells,
)


def cells_by_word(symbols, k: int) -> tuple[list[tuple[int, ...]], np.ndarray, np.ndarray]:
    """Words, corners and successors from the definition: every word of at most k belief-changing
    symbols, shortest first and in the order of its symbols; f_w(e_i) one symbol at a time (a 2-D
    product and a row normalisation per symbol); the successor after o the last k symbols of wo."""
    changing = [int(o) for o in np.flatnonzero(~symbols.identity)]
    words = [w for length in range(k + 1) for w in itertools.product(changing, repeat=length)]
    corners = []
    for word in words:
        vertices = np.diag(reachable_states(symbols).astype(float))
        for o in word:
            image = vertices @ symbols.update[o]
            total = image.sum(axis=-1, keepdims=True)
            vertices = np.divide(image, total, out=np.zeros_like(image), where=total > 0)
        corners.append(vertices)
    index = {w: c for c, w in enumerate(words)}
    successor = np.array([[c if symbols.identity[o] else index[(w + (o,))[-k:] if k else ()]
                           for o in range(symbols.n_symbols)] for c, w in enumerate(words)])
    return words, np.array(corners), successor


def still_driver(driver) -> DriverModel:
    """A driver whom nothing moves: no takeover, no failure, every trust transition the identity,
    so that every observation symbol leaves the belief as it is."""
    k, n = len(driver.incident_types), 7
    return DriverModel(trust_levels=tuple(range(1, n + 1)), incident_types=driver.incident_types,
                       takeover_probability=np.zeros((k, n)), failure_probability=np.zeros((k, n)),
                       trust_transition=np.broadcast_to(np.eye(n), (k, 2, 2, n, n)).copy(),
                       initial_belief=np.full(n, 1 / n), trust_free_takeover_probability={},
                       source_path="<still>")


def models(town, driver):
    rng = np.random.default_rng(11)
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    return {"paper": build_pomdp(town, driver),
            "three types": build_pomdp(town, lift_population(population)),
            "random": build_pomdp(town, random_driver(rng, driver.incident_types)),
            "still": build_pomdp(town, still_driver(driver))}


@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_cells_equal_their_words_corners_and_last_k_symbols(town, driver, k):
    for name, pomdp in models(town, driver).items():
        symbols = observation_symbols(pomdp)
        cells = suffix_cells(symbols, k)
        if name == "still":
            assert symbols.identity.all() and cells.n_cells == 1
        words, corners, successor = cells_by_word(symbols, k)
        assert list(cells.words) == words, name
        assert cells.vertices.tobytes() == corners.tobytes(), name
        assert (cells.next_cell == successor).all(), name


def test_atom_status_is_read_off_every_vertex_of_every_image(town, driver):
    rng = np.random.default_rng(3)
    for name, pomdp in models(town, driver).items():
        symbols = observation_symbols(pomdp)
        cells = suffix_cells(symbols, 2)
        n = pomdp.n_trust
        # five atoms: two random hyperplanes, one through the middle of the trust scale, and
        # "b[top] > m" with m the largest, then the smallest, b[top] among the corners of symbol
        # 0's image of the simplex: false (then true) at every corner but one, which lies on the
        # plane (either value: mixed)
        image = cells.vertices[0] @ symbols.update[0]
        image = image[image.sum(axis=-1) > 0]
        top = (image / image.sum(axis=-1, keepdims=True))[:, n - 1]
        coeffs = np.vstack([rng.normal(size=(2, n)), np.linspace(-1, 1, n), np.eye(n)[[n - 1, n - 1]]])
        offsets = np.array([0.1, -0.2, 0.0, top.max(), top.min()])
        status = image_label_status(cells, symbols, coeffs, offsets)
        assert status.shape == (5, cells.n_cells, symbols.n_symbols)
        assert status[3, 0, 0] == status[4, 0, 0] == 2, name
        for j, c, o in itertools.product(range(5), range(cells.n_cells), range(symbols.n_symbols)):
            seen = set()
            for vertex in cells.vertices[c]:
                image = vertex @ symbols.update[o]
                if image.sum() > 0:
                    value = offsets[j] - (image / image.sum()) @ coeffs[j]
                    seen |= ({True} if value < -LABEL_TOLERANCE else {False} if value > LABEL_TOLERANCE
                             else {True, False})
            assert status[j, c, o] == (2 if seen == {True, False} else 1 if seen == {True} else 0), \
                (name, j, c, o)
        assert image_label_status(cells, symbols, coeffs[:0], offsets[:0]).shape == (0, cells.n_cells,
                                                                                     symbols.n_symbols)

"""Questionnaires a live study asks its participants: the packaged standard scales and Likert
questionnaires from files, where in the study they are asked, and how an answer is checked.

Packaged (item texts written for trustroute after the published scales; cite the originals):

- `jian`: the 12-item trust-in-automation scale of Jian, Bisantz and Drury (2000), 7 points
  (1 = not at all, 7 = extremely); items 1-5 are distrust items, reversed when scored.
- `nasa_tlx`: NASA-TLX (Hart and Staveland, 1988), six ratings on 0-100 in steps of 5, scored
  unweighted ("raw TLX": the mean); performance runs from perfect (0) to failure (100).

A Likert questionnaire file (TOML):

    [questionnaire]
    name = "comfort"                 # letters, digits, _ and -
    title = "Comfort"
    instructions = "How much do you agree?"
    scale = { min = 1, max = 5, step = 1, low = "strongly disagree", high = "strongly agree" }
    [[questionnaire.items]]
    id = "c1"
    text = "The ride felt smooth."
    reversed = false                 # optional

A packaged questionnaire's instructions, and NASA-TLX's items, follow where it is asked (before any
drive they speak of the drives to come, at the end of all of them); a file's are its `instructions`
and items as written, wherever it is placed. The study config's `[questionnaires]` table places
them: `before` (after the consent, before any drive), `after_each_trial` (after each trial, not the
warm-up) and `end` (after the last trial), each a list of `jian`, `nasa_tlx` or file paths (relative
to the config).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import cast

from trustroute.core.errors import InputError
from trustroute.core.validation import check_keys, parse_toml, read_text
from trustroute.core.wording import shown_value

PLACEMENTS: tuple[str, ...] = ("before", "after_each_trial", "end")
QUESTIONNAIRE_KEYS: tuple[str, ...] = ("name", "title", "instructions", "scale", "items")
NAME = re.compile(r"^[a-z0-9_-]{1,40}$")
MAX_ITEMS = 100


@dataclass(frozen=True)
class Item:
    id: str
    text: str
    reversed: bool = False
    low: str = ""  # the item's own anchors (NASA-TLX's performance), else the scale's
    high: str = ""
    # ((placement, text), ...): the text where it differs by where it is asked, as the
    # questionnaire's instructions do (before any drive an item asks what one is expected to bring)
    placed: tuple[tuple[str, str], ...] = ()

    def text_for(self, placement: str) -> str:
        """The item as asked where the questionnaire is placed (a placement of PLACEMENTS)."""
        return dict(self.placed).get(placement, self.text)


@dataclass(frozen=True)
class Questionnaire:
    name: str
    title: str
    instructions: str
    items: tuple[Item, ...]
    minimum: float
    maximum: float
    step: float
    low: str
    high: str
    # ((placement, instructions), ...): the instructions where they differ by where the
    # questionnaire is asked (before any drive there is no drive "just completed"); else `instructions`
    placed: tuple[tuple[str, str], ...] = ()

    def instructions_for(self, placement: str) -> str:
        """The instructions shown where the questionnaire is asked (a placement of PLACEMENTS)."""
        return dict(self.placed).get(placement, self.instructions)

    def score(self, answers: dict[str, float]) -> float:
        """The mean item value, reversed items turned (min + max - value)."""
        values = [
            self.minimum + self.maximum - answers[i.id] if i.reversed else answers[i.id] for i in self.items
        ]
        return sum(values) / len(values)

    def check(self, answers: dict) -> dict[str, float]:
        """The answers as {item id: value}; ValueError naming the first problem."""
        if set(answers) != {item.id for item in self.items}:
            missing = sorted({item.id for item in self.items} - set(answers))
            raise ValueError(
                f"answer every item of {self.name} (missing: {', '.join(missing) or 'none'}; "
                f"unknown: {', '.join(sorted(set(answers) - {i.id for i in self.items})) or 'none'})"
            )
        for key, value in answers.items():
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not self.minimum <= value <= self.maximum   # first: a huge number goes no further
                or not whole_steps(value, self.minimum, self.step)
            ):
                raise ValueError(
                    f"{self.name}.{key}: {shown_value(value, 24)} is not on the scale "
                    f"{self.minimum:g}-{self.maximum:g} in steps of {self.step:g}"
                )
        return {key: float(value) for key, value in answers.items()}

    def to_client(self, placement: str) -> dict:
        """What the station shows where the questionnaire is asked (no scoring keys)."""
        return {
            "name": self.name,
            "title": self.title,
            "instructions": self.instructions_for(placement),
            "scale": {
                "min": self.minimum,
                "max": self.maximum,
                "step": self.step,
                "low": self.low,
                "high": self.high,
            },
            "items": [{"id": i.id, "text": i.text_for(placement), "low": i.low, "high": i.high}
                      for i in self.items],
        }


def as_written(number: float) -> Fraction:
    """The number exactly as written: an int as it is, a float by its shortest decimal form (0.1 is
    one tenth, not the binary fraction nearest to it)."""
    return Fraction(number) if isinstance(number, int) else Fraction(repr(float(number)))


def whole_steps(value: float, start: float, step: float) -> bool:
    """Whether `value` is `start` plus a whole number of `step`s, in exact arithmetic: no tolerance
    lets a number between two points of a scale pass as one."""
    if any(isinstance(x, float) and not math.isfinite(x) for x in (value, start, step)) or not step:
        return False
    return ((as_written(value) - as_written(start)) / as_written(step)).denominator == 1


JIAN_TEXTS = (
    ("j1", "The automated vehicle is deceptive.", True),
    ("j2", "The automated vehicle behaves in an underhanded manner.", True),
    ("j3", "I am suspicious of the automated vehicle's intent, actions or outputs.", True),
    ("j4", "I am wary of the automated vehicle.", True),
    ("j5", "The automated vehicle's actions will have a harmful or injurious outcome.", True),
    ("j6", "I am confident in the automated vehicle.", False),
    ("j7", "The automated vehicle provides security.", False),
    ("j8", "The automated vehicle has integrity.", False),
    ("j9", "The automated vehicle is dependable.", False),
    ("j10", "The automated vehicle is reliable.", False),
    ("j11", "I can trust the automated vehicle.", False),
    ("j12", "I am familiar with the automated vehicle.", False),
)
JIAN = Questionnaire(
    "jian",
    "Trust in automation (Jian, Bisantz and Drury, 2000)",
    "Rate how much each statement applies to the automated vehicle you just rode in.",
    tuple(Item(key, text, reverse) for key, text, reverse in JIAN_TEXTS),
    1,
    7,
    1,
    "not at all",
    "extremely",
    (
        ("before", "Rate how much each statement applies to the automated vehicle you are about to ride in."),
        ("end", "Rate how much each statement applies to the automated vehicle you rode in today."),
    ),
)
# NASA-TLX's items where they are asked other than after a trial: before any drive, what a drive is
# expected to bring (as the instructions there ask); at the end, the session's drives
TLX_PLACED: dict[str, tuple[tuple[str, str], ...]] = {
    "mental": (("before", "Mental demand: how mentally demanding do you expect a drive to be?"),
               ("end", "Mental demand: how mentally demanding were the drives?")),
    "physical": (("before", "Physical demand: how physically demanding do you expect a drive to be?"),
                 ("end", "Physical demand: how physically demanding were the drives?")),
    "temporal": (("before", "Temporal demand: how hurried or rushed do you expect the pace of a drive "
                  "to be?"),
                 ("end", "Temporal demand: how hurried or rushed was the pace of the drives?")),
    "performance": (("before", "Performance: how successful do you expect to be in doing what you are asked "
                     "to do?"),),
    "effort": (("before", "Effort: how hard do you expect to have to work to reach your level of "
                "performance?"),),
    "frustration": (("before", "Frustration: how insecure, discouraged, irritated, stressed and annoyed do "
                     "you expect to be?"),),
}
NASA_TLX = Questionnaire(
    "nasa_tlx",
    "Workload (NASA-TLX)",
    "Rate the drive you just completed on each scale.",
    (
        Item("mental", "Mental demand: how mentally demanding was the drive?", placed=TLX_PLACED["mental"]),
        Item("physical", "Physical demand: how physically demanding was the drive?",
             placed=TLX_PLACED["physical"]),
        Item("temporal", "Temporal demand: how hurried or rushed was the pace of the drive?",
             placed=TLX_PLACED["temporal"]),
        Item(
            "performance",
            "Performance: how successful were you in doing what you were asked to do?",
            low="perfect",
            high="failure",
            placed=TLX_PLACED["performance"],
        ),
        Item("effort", "Effort: how hard did you have to work to reach your level of performance?",
             placed=TLX_PLACED["effort"]),
        Item(
            "frustration",
            "Frustration: how insecure, discouraged, irritated, stressed and annoyed were you?",
            placed=TLX_PLACED["frustration"],
        ),
    ),
    0,
    100,
    5,
    "very low",
    "very high",
    (
        ("before", "You have not driven yet: rate the workload you expect a drive to bring on each scale."),
        ("end", "Rate the drives of this session as a whole on each scale."),
    ),
)
PACKAGED: dict[str, Questionnaire] = {"jian": JIAN, "nasa_tlx": NASA_TLX}


def load_questionnaire(path: Path, source: str) -> Questionnaire:
    """A Likert questionnaire file (the module's format), or InputError naming the place and fix."""
    shown = str(path)
    data = parse_toml(
        read_text(path, shown, "the questionnaire", "pass an existing TOML file"), shown, "questionnaire"
    )
    table = data.get("questionnaire") if isinstance(data, dict) else None

    def bad(place: str, problem: str, fix: str) -> InputError:
        return InputError(shown, f"questionnaire.{place}" if place else "questionnaire", problem, fix)

    if not isinstance(table, dict):
        raise bad("", "missing [questionnaire] table", "start the file with [questionnaire]")
    check_keys(table, QUESTIONNAIRE_KEYS, shown, "questionnaire", "questionnaire")
    name = table.get("name")
    if not isinstance(name, str) or not NAME.match(name) or name in PACKAGED:
        raise bad(
            "name",
            f"{name!r} is not a usable name",
            "give lower-case letters, digits, _ or - (not jian or nasa_tlx)",
        )
    scale = table.get("scale")
    if not isinstance(scale, dict) or set(scale) - {"min", "max", "step", "low", "high"}:
        raise bad("scale", "expected { min, max, step, low, high }", "write scale = { min = 1, max = 5 }")
    low, high, step = scale.get("min"), scale.get("max"), scale.get("step", 1)
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in (low, high, step)):
        raise bad(
            "scale", "min < max with max - min a multiple of step (> 0) is needed", "e.g. min = 1, max = 7"
        )
    low, high, step = cast(float, low), cast(float, high), cast(float, step)  # checked numbers above
    if not low < high or step <= 0 or not whole_steps(high, low, step):
        raise bad(
            "scale", "min < max with max - min a multiple of step (> 0) is needed", "e.g. min = 1, max = 7"
        )
    items = table.get("items")
    if not isinstance(items, list) or not 2 <= len(items) <= MAX_ITEMS:
        raise bad("items", f"expected 2 to {MAX_ITEMS} [[questionnaire.items]]", "add the items")
    parsed = []
    for index, item in enumerate(items):
        if (
            not isinstance(item, dict)
            or set(item) - {"id", "text", "reversed"}
            or not isinstance(item.get("id"), str)
            or not NAME.match(item["id"])
            or not isinstance(item.get("text"), str)
            or not item["text"].strip()
            or not isinstance(item.get("reversed", False), bool)
        ):
            raise bad(
                f"items[{index}]",
                "expected id (letters, digits, _ -), text and optional reversed",
                'write { id = "q1", text = "...", reversed = false }',
            )
        parsed.append(Item(item["id"], item["text"].strip(), item.get("reversed", False)))
    if len({item.id for item in parsed}) != len(parsed):
        raise bad("items", "item ids repeat", "give every item its own id")
    return Questionnaire(
        name,
        str(table.get("title", name)),
        str(table.get("instructions", "")),
        tuple(parsed),
        low,
        high,
        step,
        str(scale.get("low", "")),
        str(scale.get("high", "")),
    )


def questionnaire_plan(table: dict | None, base: Path, source: str) -> dict[str, tuple[Questionnaire, ...]]:
    """The study config's [questionnaires] table: {placement: questionnaires}; InputError if bad."""
    plan: dict[str, tuple[Questionnaire, ...]] = {placement: () for placement in PLACEMENTS}
    if table is None:
        return plan
    check_keys(table, PLACEMENTS, source, "questionnaires", "[questionnaires] table")
    for placement in PLACEMENTS:
        entries = table.get(placement, [])
        if not isinstance(entries, list) or not all(isinstance(e, str) and e for e in entries):
            raise InputError(
                source,
                f"questionnaires.{placement}",
                "expected a list of names or files",
                'e.g. after_each_trial = ["jian", "nasa_tlx"]',
            )
        found = []
        for entry in entries:
            if entry in PACKAGED:
                found.append(PACKAGED[entry])
            else:
                path = Path(entry) if Path(entry).is_absolute() else base / entry
                found.append(load_questionnaire(path, source))
        if len({q.name for q in found}) != len(found):
            raise InputError(
                source, f"questionnaires.{placement}", "a questionnaire appears twice", "list each once"
            )
        plan[placement] = tuple(found)
    return plan


def resolved_table(table: dict | None, base: Path, source: str) -> dict | None:
    """The [questionnaires] table checked, its files made absolute (what the config keeps)."""
    if table is None:
        return None
    questionnaire_plan(table, base, source)
    return {
        placement: [
            entry if entry in PACKAGED or Path(entry).is_absolute() else str((base / entry).resolve())
            for entry in table.get(placement, [])
        ]
        for placement in PLACEMENTS
    }

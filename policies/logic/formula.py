"""scLDTL formulas: the abstract syntax tree, its parser and printer, and a canonical form.

Grammar (docs/formats/spec.md, "Formula grammar"), lowest precedence first:

    formula := or
    or      := and ('|' and)*
    and     := until ('&' until)*
    until   := unary ('U' until)?          (right-associative)
    unary   := '!' unary | 'X' unary | 'F' unary | primary
    primary := 'true' | 'false' | ATOM | '(' formula ')'

Negation applies to atoms only (`!a`, `!(a)`, `!!a`, `!true`); `G` and the negation of a compound
formula are rejected as not co-safe. Errors are `FormulaError` (an InputError) with the 0-based
offset into the formula text; `policies.spec` turns it into a file line and column.

The canonical constructors (`make_and`, `make_or`, `make_next`, `make_eventually`, `make_until`)
flatten, sort, deduplicate and apply absorption and constant simplifications, so that formula
progression (policies/logic/dfa.py) reaches a finite set of syntactically distinct obligations.
Every node carries a `key` (a compact prefix notation of the canonical structure) used for
ordering, hashing and equality, so large formulas hash in constant time.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Collection, Iterable, Iterator
from dataclasses import dataclass, field

from trustroute.core.errors import InputError

KEYWORDS = frozenset({"true", "false", "X", "F", "U", "G"})
ATOM_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


# -- AST ----------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class _Node:
    key: str = field(init=False, repr=False, compare=False)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Node) and self.key == other.key

    def __hash__(self) -> int:
        return hash(self.key)

    def __str__(self) -> str:
        return format_formula(self)  # type: ignore[arg-type]


@dataclass(frozen=True, eq=False)
class Const(_Node):
    value: bool

    def __post_init__(self) -> None:
        object.__setattr__(self, "key", "1" if self.value else "0")


@dataclass(frozen=True, eq=False)
class Literal(_Node):
    """An atom (`positive`) or its negation, read at the position where it is evaluated."""

    atom: str
    positive: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "key", self.atom if self.positive else "!" + self.atom)


@dataclass(frozen=True, eq=False)
class Now(_Node):
    """A literal of the position being read (only inside progression; never parsed or printed)."""

    atom: str
    positive: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "key", "@" + (self.atom if self.positive else "!" + self.atom))


@dataclass(frozen=True, eq=False)
class And(_Node):
    parts: tuple[Formula, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "key", "&(" + ",".join(p.key for p in self.parts) + ")")


@dataclass(frozen=True, eq=False)
class Or(_Node):
    parts: tuple[Formula, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "key", "|(" + ",".join(p.key for p in self.parts) + ")")


@dataclass(frozen=True, eq=False)
class Next(_Node):
    body: Formula

    def __post_init__(self) -> None:
        object.__setattr__(self, "key", "X(" + self.body.key + ")")


@dataclass(frozen=True, eq=False)
class Eventually(_Node):
    body: Formula

    def __post_init__(self) -> None:
        object.__setattr__(self, "key", "F(" + self.body.key + ")")


@dataclass(frozen=True, eq=False)
class Until(_Node):
    left: Formula
    right: Formula

    def __post_init__(self) -> None:
        object.__setattr__(self, "key", "U(" + self.left.key + "," + self.right.key + ")")


Formula = Const | Literal | Now | And | Or | Next | Eventually | Until

TRUE = Const(True)
FALSE = Const(False)


def atoms_in_order(formula: Formula) -> tuple[str, ...]:
    """Atom names in order of first occurrence, left to right."""
    seen: dict[str, None] = {}
    for node in walk(formula):
        if isinstance(node, Literal | Now):
            seen.setdefault(node.atom, None)
    return tuple(seen)


def walk(formula: Formula) -> Iterator[Formula]:
    """Every node, pre-order, left to right."""
    yield formula
    if isinstance(formula, And | Or):
        for part in formula.parts:
            yield from walk(part)
    elif isinstance(formula, Next | Eventually):
        yield from walk(formula.body)
    elif isinstance(formula, Until):
        yield from walk(formula.left)
        yield from walk(formula.right)


def map_literals(formula: Formula, replace: Callable[[Literal], Formula]) -> Formula:
    """Rebuild `formula` canonically with every Literal replaced by `replace(literal)`."""
    if isinstance(formula, Literal):
        return replace(formula)
    if isinstance(formula, And):
        return make_and(map_literals(p, replace) for p in formula.parts)
    if isinstance(formula, Or):
        return make_or(map_literals(p, replace) for p in formula.parts)
    if isinstance(formula, Next):
        return make_next(map_literals(formula.body, replace))
    if isinstance(formula, Eventually):
        return make_eventually(map_literals(formula.body, replace))
    if isinstance(formula, Until):
        return make_until(map_literals(formula.left, replace), map_literals(formula.right, replace))
    return formula


# -- canonical form -----------------------------------------------------------------------------

def _negated(part: Formula) -> Formula | None:
    if isinstance(part, Literal):
        return Literal(part.atom, not part.positive)
    if isinstance(part, Now):
        return Now(part.atom, not part.positive)
    return None


def _junction(parts: Iterable[Formula], conjunction: bool) -> Formula:
    kind, unit, zero = (And, TRUE, FALSE) if conjunction else (Or, FALSE, TRUE)
    other = Or if conjunction else And
    flat: dict[str, Formula] = {}
    for part in parts:
        members = part.parts if isinstance(part, kind) else (part,)
        for member in members:
            if isinstance(member, Const):
                if member.value == zero.value:
                    return zero
                continue  # the unit
            flat.setdefault(member.key, member)
    for member in flat.values():
        negated = _negated(member)
        if negated is not None and negated.key in flat:
            return zero  # a & !a, a | !a
    # Absorption: a & (a | b) = a, a | (a & b) = a.
    kept = [m for m in flat.values()
            if not (isinstance(m, other) and any(p.key in flat for p in m.parts))]
    if not kept:
        return unit
    if len(kept) == 1:
        return kept[0]
    return kind(tuple(sorted(kept, key=lambda m: m.key)))


def make_and(parts: Iterable[Formula]) -> Formula:
    return _junction(parts, conjunction=True)


def make_or(parts: Iterable[Formula]) -> Formula:
    return _junction(parts, conjunction=False)


def make_next(body: Formula) -> Formula:
    return body if isinstance(body, Const) else Next(body)  # X true = true, X false = false


def make_eventually(body: Formula) -> Formula:
    if isinstance(body, Const | Eventually):
        return body  # F true, F false, F F a = F a
    return Eventually(body)


def make_until(left: Formula, right: Formula) -> Formula:
    if isinstance(right, Const):
        return right
    if left == TRUE:
        return make_eventually(right)
    if left == FALSE or left == right:
        return right
    return Until(left, right)


def canonical(formula: Formula) -> Formula:
    """The canonical form of `formula` (same meaning, normalised structure)."""
    if isinstance(formula, And):
        return make_and(canonical(p) for p in formula.parts)
    if isinstance(formula, Or):
        return make_or(canonical(p) for p in formula.parts)
    if isinstance(formula, Next):
        return make_next(canonical(formula.body))
    if isinstance(formula, Eventually):
        return make_eventually(canonical(formula.body))
    if isinstance(formula, Until):
        return make_until(canonical(formula.left), canonical(formula.right))
    return formula


def disjunctive_normal_form(formula: Formula) -> Formula:
    """The minimal DNF of `formula` seen as a positive Boolean combination of its non-Boolean
    nodes (literals and temporal subformulas): an antichain of conjunctions, unique for that view.

    Formula progression keeps producing nested And/Or of the same temporal subformulas
    (e.g. `F p U F q`); the nesting grows without bound unless states are normalised like this.
    With finitely many temporal subformulas there are then finitely many states."""
    terms = _dnf_terms(formula)
    return make_or(make_and(term) for term in sorted(terms, key=lambda t: sorted(p.key for p in t)))


def _minimal(terms: Iterable[frozenset[Formula]]) -> set[frozenset[Formula]]:
    unique = set(terms)
    return {t for t in unique if not any(o < t for o in unique)}


def _dnf_terms(formula: Formula) -> set[frozenset[Formula]]:
    if isinstance(formula, Const):
        return {frozenset()} if formula.value else set()
    if isinstance(formula, Or):
        return _minimal(t for p in formula.parts for t in _dnf_terms(p))
    if isinstance(formula, And):
        terms: set[frozenset[Formula]] = {frozenset()}
        for part in formula.parts:
            product = []
            for left in terms:
                for right in _dnf_terms(part):
                    term = left | right
                    if not any(n is not None and n in term for n in map(_negated, term)):
                        product.append(term)  # skip terms with a & !a
            terms = _minimal(product)
        return terms
    return {frozenset((formula,))}


# -- printing -----------------------------------------------------------------------------------

_LEVEL = {Or: 0, And: 1, Until: 2}


def _level(formula: Formula) -> int:
    return _LEVEL.get(type(formula), 3)


def format_formula(formula: Formula) -> str:
    """Text that parses back to the same AST (minimal parentheses)."""
    if isinstance(formula, Const):
        return "true" if formula.value else "false"
    if isinstance(formula, Literal):
        return formula.atom if formula.positive else "!" + formula.atom
    if isinstance(formula, Now):
        return ("@" if formula.positive else "@!") + formula.atom
    if isinstance(formula, And | Or):
        level = _level(formula)
        # Same-kind children need parentheses too: the parser flattens a & b & c into one node.
        texts = [f"({format_formula(p)})" if _level(p) <= level else format_formula(p)
                 for p in formula.parts]
        return (" & " if isinstance(formula, And) else " | ").join(texts)
    if isinstance(formula, Next | Eventually):
        body = format_formula(formula.body)
        operator = "X" if isinstance(formula, Next) else "F"
        return f"{operator} ({body})" if _level(formula.body) < 3 else f"{operator} {body}"
    if isinstance(formula, Until):
        left = format_formula(formula.left)
        right = format_formula(formula.right)
        left = f"({left})" if _level(formula.left) <= 2 else left
        right = f"({right})" if _level(formula.right) < 2 else right
        return f"{left} U {right}"
    raise TypeError(f"not a formula: {formula!r}")


# -- parsing ------------------------------------------------------------------------------------

NEAR_CHARS = 24  # of the formula shown from the offending offset on


class FormulaError(InputError):
    """A formula that does not parse or is not co-safe, at `offset` (0-based) in `text`: placed at
    the file's line and column of the `formula` key, the problem ending with the text there."""

    def __init__(self, text: str, offset: int, problem: str, fix: str, source: str = "<formula>",
                 line: int = 1, column: int = 1) -> None:
        self.text = text
        self.offset = offset
        self.line = line
        self.column = column + offset
        super().__init__(source, f"line {line} column {self.column} (formula)", problem + self.near(), fix)

    def near(self) -> str:
        """`, near '...'`: the formula from the offending offset on (empty at the end of the text,
        which the problem names)."""
        rest = self.text[self.offset:].strip()
        if not rest:
            return ""
        return f", near '{rest if len(rest) <= NEAR_CHARS else rest[:NEAR_CHARS - 3] + '...'}'"


@dataclass(frozen=True)
class _Token:
    kind: str      # "atom", "(", ")", "!", "&", "|", "U", "X", "F", "G", "true", "false", "end"
    text: str
    offset: int


_SYMBOLS = {"(": "(", ")": ")", "!": "!", "&": "&", "|": "|"}
_GRAMMAR_FIX = "scLDTL allows true, false, atoms, !atom, &, |, X, F, U and parentheses"


class _Parser:
    def __init__(self, text: str, known_atoms: Collection[str] | None, source: str, line: int,
                 column: int) -> None:
        self.text = text
        self.known_atoms = known_atoms
        self.source, self.line, self.column = source, line, column
        self.tokens = self._tokenize()
        self.position = 0

    def error(self, offset: int, problem: str, fix: str = _GRAMMAR_FIX) -> FormulaError:
        return FormulaError(self.text, offset, problem, fix, self.source, self.line, self.column)

    def _tokenize(self) -> list[_Token]:
        tokens: list[_Token] = []
        i = 0
        text = self.text
        while i < len(text):
            char = text[i]
            if char.isspace():
                i += 1
                continue
            if char in _SYMBOLS:
                if text.startswith(("&&", "||"), i):
                    raise self.error(i, f"unexpected '{text[i:i + 2]}': expected '{char}'",
                                     f"write a single '{char}'")
                tokens.append(_Token(_SYMBOLS[char], char, i))
                i += 1
                continue
            match = ATOM_PATTERN.match(text, i)
            if match:
                word = match.group()
                kind = word if word in KEYWORDS else "atom"
                tokens.append(_Token(kind, word, i))
                i = match.end()
                continue
            if text.startswith(("->", "<->", "=>"), i):
                raise self.error(i, "implication is not part of scLDTL (it negates a formula, which "
                                 "is not co-safe in general)", "rewrite with ! on atoms, & and |")
            hint = "write '!' for negation" if char == "~" else _GRAMMAR_FIX
            raise self.error(i, f"unexpected character {char!r}: expected an atom, an operator "
                             "or a parenthesis", hint)
        tokens.append(_Token("end", "", len(text)))
        return tokens

    def peek(self) -> _Token:
        return self.tokens[self.position]

    def advance(self) -> _Token:
        token = self.tokens[self.position]
        self.position += 1
        return token

    def parse(self) -> Formula:
        if self.peek().kind == "end":
            raise self.error(0, "empty formula: expected a formula such as 'F (v1 & hightrust)'",
                             "write the formula in the 'formula' key")
        formula = self.parse_or()
        token = self.peek()
        if token.kind == ")":
            raise self.error(token.offset, "unbalanced parentheses: ')' without a matching '('",
                             "remove the ')' or add the matching '('")
        if token.kind != "end":
            raise self.error(token.offset, f"expected an operator (&, |, U) or the end of the "
                             f"formula, found {self.describe(token)}")
        return formula

    def describe(self, token: _Token) -> str:
        return "the end of the formula" if token.kind == "end" else f"'{token.text}'"

    def parse_or(self) -> Formula:
        parts = [self.parse_and()]
        while self.peek().kind == "|":
            self.advance()
            parts.append(self.parse_and())
        return parts[0] if len(parts) == 1 else Or(tuple(parts))

    def parse_and(self) -> Formula:
        parts = [self.parse_until()]
        while self.peek().kind == "&":
            self.advance()
            parts.append(self.parse_until())
        return parts[0] if len(parts) == 1 else And(tuple(parts))

    def parse_until(self) -> Formula:
        left = self.parse_unary()
        if self.peek().kind == "U":
            self.advance()
            return Until(left, self.parse_until())
        return left

    def parse_unary(self) -> Formula:
        token = self.peek()
        if token.kind == "!":
            self.advance()
            body = self.parse_unary()
            if isinstance(body, Literal):
                return Literal(body.atom, not body.positive)
            if isinstance(body, Const):
                return Const(not body.value)
            raise self.error(token.offset, "negation of a compound formula is not co-safe: '!' "
                             "applies to atoms only", "push the negation down to the atoms "
                             "(e.g. !(a & b) as !a | !b); !F and !X cannot be expressed")
        if token.kind in ("X", "F"):
            self.advance()
            body = self.parse_unary()
            return Next(body) if token.kind == "X" else Eventually(body)
        if token.kind == "G":
            raise self.error(token.offset, "'G' (globally) is not co-safe: no finite prefix "
                             "can prove it", "use a co-safe property, e.g. '!bad U goal' instead "
                             "of 'G !bad & F goal'")
        return self.parse_primary()

    def parse_primary(self) -> Formula:
        token = self.advance()
        if token.kind in ("true", "false"):
            return Const(token.kind == "true")
        if token.kind == "atom":
            if self.known_atoms is not None and token.text not in self.known_atoms:
                defined = ", ".join(sorted(self.known_atoms)) or "none"
                raise self.error(token.offset, f"unknown atom '{token.text}': expected one of the "
                                 f"atoms defined in the spec ({defined})",
                                 f"define '{token.text}' under [states], [beliefs.{token.text}] "
                                 "or [trust_states]")
            return Literal(token.text)
        if token.kind == "(":
            inner = self.parse_or()
            closing = self.peek()
            if closing.kind != ")":
                raise self.error(closing.offset, f"unbalanced parentheses: expected ')' to close the "
                                 f"'(' at column {self.column + token.offset}, found "
                                 f"{self.describe(closing)}", "add the missing ')'")
            self.advance()
            return inner
        if token.kind == ")":
            raise self.error(token.offset, "expected a formula before ')'",
                             "remove the ')' or write a formula inside the parentheses")
        raise self.error(token.offset, f"expected a formula (an atom, 'true', 'false', '!', 'X', "
                         f"'F' or '('), found {self.describe(token)}")


def parse_formula(text: str, known_atoms: Collection[str] | None = None, source: str = "<formula>",
                  line: int = 1, column: int = 1) -> Formula:
    """Parse scLDTL text into an AST; `known_atoms` (if given) rejects undefined atoms.

    `line`/`column` locate the formula's first character in its file, for error messages.
    """
    return _Parser(text, known_atoms, source, line, column).parse()

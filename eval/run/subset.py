"""Which cases the full-resolution baselines run on (``dataset.baseline_cases``).
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/experiments.md.

- ``per_pose`` (DeFAUST's default): one case per target pose, from different subjects.
  With the target poses present sorted ``p_0 < p_1 < ...`` and the subjects present
  sorted ``s_0 < s_1 < ...`` (``n`` of them), pose ``p_j`` is taken from subject
  ``s_(j mod n)`` (for DeFAUST's poses 1..4 and subjects 0..9: pose ``p`` from subject
  ``(p - 1) mod 10``, i.e. s00_p01, s01_p02, s02_p03, s03_p04); when that subject has no
  such case (e.g. after ``dataset.limit``), the next subject in that cyclic order that
  has it.
- an integer ``N``: the first ``N`` cases (the dataset's order); ``0``: none.
- ``all`` or null: every case."""
from __future__ import annotations

from sshade.errors import SShaDeError

__all__ = ["baseline_selection", "check_baseline_cases", "check_method_cases", "method_selections", "PER_POSE"]

PER_POSE = "per_pose"


def check_baseline_cases(v):
    """``dataset.baseline_cases`` checked: None (= all), ``"all"``, ``"per_pose"`` or an
    int >= 0 (bools refused; numeric strings accepted). Raises SShaDeError naming the key.

    >>> check_baseline_cases("per_pose"), check_baseline_cases("3"), check_baseline_cases(None)
    ('per_pose', 3, None)
    """
    if v is None or isinstance(v, str) and v.strip().lower() in ("all", "null", "none"):
        return None
    if isinstance(v, str) and v.strip().lower() == PER_POSE:
        return PER_POSE
    if not isinstance(v, bool):
        try:
            n = int(str(v).strip())
            if n >= 0 and str(n) == str(v).strip():
                return n
        except ValueError:
            pass
    raise SShaDeError(f"dataset.baseline_cases must be all, per_pose or an integer >= 0 (the first N cases), "
                      f"got {v!r}")


def _per_pose(cases) -> set[int]:
    poses = sorted({c.pose for c in cases if c.pose is not None})
    subjects = sorted({c.subject for c in cases if c.subject is not None})
    where = {(c.subject, c.pose): i for i, c in reversed(list(enumerate(cases)))}  # the first case of a pair
    out = set()
    for j, p in enumerate(poses):
        for k in range(len(subjects)):
            i = where.get((subjects[(j + k) % len(subjects)], p))
            if i is not None:
                out.add(i)
                break
    return out


def baseline_selection(cases, spec) -> tuple[set[int] | None, str]:
    """``(indices, rule)``: the indices of ``cases`` (objects with ``subject`` and
    ``pose``) the baselines run on (None: every case) and the rule in words, for the table.

    >>> from types import SimpleNamespace as C
    >>> cs = [C(subject=s, pose=p) for s in range(3) for p in (1, 2)]
    >>> baseline_selection(cs, "per_pose")
    ({0, 3}, 'per_pose: one case per target pose, pose p_j from subject s_(j mod 3) (2 cases)')
    >>> baseline_selection(cs, 1)[1], baseline_selection(cs, "all")
    ('the first 1 case(s)', (None, 'all cases'))

    Raises SShaDeError for a bad ``spec`` (:func:`check_baseline_cases`).
    """
    spec = check_baseline_cases(spec)
    if spec is None:
        return None, "all cases"
    if spec == PER_POSE:
        sel = _per_pose(cases)
        n_subj = len({c.subject for c in cases if c.subject is not None})
        return sel, (f"per_pose: one case per target pose, pose p_j from subject s_(j mod {n_subj}) "
                     f"({len(sel)} cases)")
    return set(range(min(spec, len(cases)))), f"the first {spec} case(s)"


def check_method_cases(spec, names=None) -> dict:
    """``method_cases`` checked: None / empty = {}; else a mapping of method names (among
    ``names`` when given) to :func:`check_baseline_cases` rules. Returns a plain dict.

    >>> check_method_cases({"Implicit-ARAP": "per_pose"}, ["SShaDe", "Implicit-ARAP"])
    {'Implicit-ARAP': 'per_pose'}

    Raises SShaDeError for a value that is not a mapping, a name not among ``names``, or
    a bad rule.
    """
    if spec is None:
        return {}
    try:
        items = dict(spec.items())
    except AttributeError:
        raise SShaDeError(f"method_cases must be a mapping of method names to case rules (all, per_pose or an "
                          f"integer), e.g. {{Implicit-ARAP: per_pose}}; got {spec!r}") from None
    out = {}
    for k, v in items.items():
        if names is not None and str(k) not in names:
            raise SShaDeError(f"method_cases names {k!r}, which is not among the methods run ({list(names)})")
        try:
            out[str(k)] = check_baseline_cases(v)
        except SShaDeError as e:
            raise SShaDeError(f"method_cases.{k}: {e}") from None
    return out


def method_selections(cases, spec, names) -> dict:
    """``{name: (indices or None, rule in words)}`` for each method ``spec``
    (``method_cases``, :func:`check_method_cases`) gives its own rule; see
    :func:`baseline_selection`.

    >>> from types import SimpleNamespace as C
    >>> cs = [C(subject=s, pose=p) for s in range(3) for p in (1, 2)]
    >>> method_selections(cs, {"Implicit-ARAP": 1}, ["SShaDe", "Implicit-ARAP"])
    {'Implicit-ARAP': ({0}, 'the first 1 case(s)')}

    Raises SShaDeError as :func:`check_method_cases`.
    """
    return {k: baseline_selection(cases, v) for k, v in check_method_cases(spec, names).items()}

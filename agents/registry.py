"""The registry of named policies: one record per name, carrying what every list of policies reads.

An entry (:class:`PolicyEntry`) says how to build the policy (``factory``), what it is (``kind``), the
envs it acts on, what it does in one line, and the lists it is on: the paper's table (``table``: the
README's rows, ``lawn benchmark``'s default), the paper's own comparison (``paper``), the task suite
(``suite``) and the paper's experiments' experts (``experiments``). Those lists are views of the registry
(:class:`Names`), read at each use, in registration order; the command line's policy names are its keys.
So a new policy needs one entry and nothing else::

    from agents.registry import PolicyEntry, register

    register(PolicyEntry("my-mpc", MyMPCPolicy, "expert", "what it does, in one line", suite=True))

:func:`register` refuses a name already taken; :class:`PolicyEntry` refuses a malformed entry, naming the
field, the value and what is allowed. The built-in entries are :data:`agents.policies.BUILT_IN_POLICIES`.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Literal, get_args, overload

import lawn_env

from .base import Policy

__all__ = ["Kind", "KINDS", "Flag", "FLAGS", "PolicyFactory", "PolicyEntry", "POLICIES", "register", "unregister",
           "Names"]

#: What a policy is: one of the experts (planners that optimize the slot), a baseline (the paper's
#: comparisons, fixed laws), a reference (not a controller: it measures, like ``global-mpc``'s gaps) or a
#: learned agent registered under a name (the name forms ``zoo:``, ``sb3:``, ... are agents.learned's).
Kind = Literal["expert", "baseline", "reference", "learned"]
KINDS: tuple[str, ...] = get_args(Kind)
#: The lists an entry can be on (:class:`PolicyEntry`'s boolean fields of the same names).
Flag = Literal["table", "paper", "suite", "experiments"]
FLAGS: tuple[str, ...] = get_args(Flag)
#: What builds a policy: ``factory(config, env_id=..., seed=..., **settings)`` (a :class:`~agents.base.Policy`
#: class, or a function returning one).
PolicyFactory = Callable[..., Policy]

_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
#: The kinds each list takes: the table and the suite compare controllers; the experiments study experts.
_LIST_KINDS: dict[str, tuple[str, ...]] = {"table": ("expert", "baseline"), "paper": ("expert", "baseline"),
                                           "suite": ("expert", "baseline"), "experiments": ("expert",)}


@dataclass(frozen=True)
class PolicyEntry:
    """One named policy and the lists it is on; validated on construction (each message names the field,
    the value and what is allowed)."""

    name: str
    """The policy's name (``make_policy(name)``, ``lawn evaluate --policy NAME``): letters, digits, ``.``,
    ``_``, ``-``; no ``:`` (the learned agents', anchors' and reference rows' name forms)."""
    factory: PolicyFactory
    """Builds the policy: ``factory(config, env_id=..., seed=..., **settings)``."""
    kind: Kind
    description: str
    """What the policy is, in one line."""
    table: bool = False
    """On the paper's (and the README's) table: ``agents.BENCHMARK_POLICIES``, ``lawn benchmark``'s rows."""
    paper: bool = False
    """One of the paper's own comparison, its expert and its baselines (``agents.PAPER_POLICIES``); on the table."""
    suite: bool = False
    """In the task suite (``evaluation.protocols.SUITE_POLICIES``, before its anchors)."""
    experiments: bool = False
    """One of the experts of the paper's experiments (``paper.experiments.base.EXPERTS``)."""
    env_ids: tuple[str, ...] = ()
    """The env ids it acts on (of ``lawn_env.ENV_IDS``); empty: those its factory declares (``factory.env_ids``,
    a :class:`~agents.base.Policy` class's)."""

    def __post_init__(self) -> None:
        if not (isinstance(self.name, str) and _NAME.fullmatch(self.name)):
            raise ValueError(f"name={self.name!r}: a policy's name is letters, digits, '.', '_' and '-', starting "
                             "with a letter or digit (no ':', which the learned agents' and anchors' names use)")
        if not callable(self.factory):
            raise ValueError(f"factory={self.factory!r} of {self.name!r}: must be callable (a Policy class, or a "
                             "function factory(config, env_id=..., seed=..., **settings) returning one)")
        if self.kind not in KINDS:
            raise ValueError(f"kind={self.kind!r} of {self.name!r}: must be one of {', '.join(KINDS)}")
        if not (isinstance(self.description, str) and self.description.strip() and "\n" not in self.description):
            raise ValueError(f"description={self.description!r} of {self.name!r}: must be one non-empty line")
        for flag in FLAGS:
            self._check_flag(flag)
        object.__setattr__(self, "env_ids", self._checked_env_ids())

    def _check_flag(self, flag: str) -> None:
        value = getattr(self, flag)
        if not isinstance(value, bool):
            raise ValueError(f"{flag}={value!r} of {self.name!r}: must be True or False")
        if value and self.kind not in _LIST_KINDS[flag]:
            raise ValueError(f"{flag}=True of {self.name!r}, kind={self.kind!r}: the {flag} list takes kinds "
                             f"{', '.join(_LIST_KINDS[flag])}")
        if flag == "paper" and value and not self.table:
            raise ValueError(f"paper=True of {self.name!r}: the paper's comparison is on the table (set table=True)")

    def _checked_env_ids(self) -> tuple[str, ...]:
        declared = getattr(self.factory, "env_ids", None)
        env_ids = tuple(self.env_ids) or (tuple(declared) if declared is not None else ())
        if not env_ids:
            raise ValueError(f"env_ids=() of {self.name!r}: its factory declares none (no env_ids attribute); give "
                             f"the env ids it acts on, of {', '.join(lawn_env.ENV_IDS)}")
        unknown = [e for e in env_ids if e not in lawn_env.ENV_IDS]
        if unknown:
            raise ValueError(f"env_ids={env_ids!r} of {self.name!r}: {', '.join(map(repr, unknown))} not an env id; "
                             f"valid: {', '.join(lawn_env.ENV_IDS)}")
        if declared is not None and set(env_ids) - set(declared):
            raise ValueError(f"env_ids={env_ids!r} of {self.name!r}: its factory drives {', '.join(declared)} only")
        return env_ids


_ENTRIES: dict[str, PolicyEntry] = {}
#: The registered policies by name, in registration order (read-only: :func:`register` adds to it).
POLICIES: Mapping[str, PolicyEntry] = MappingProxyType(_ENTRIES)


def register(entry: PolicyEntry) -> PolicyEntry:
    """Add ``entry`` to the registry (and so to every list its flags name); returns it. A name already
    registered is refused (:func:`unregister` it first to replace it)."""
    if not isinstance(entry, PolicyEntry):
        raise TypeError(f"entry={entry!r}: register takes a PolicyEntry")
    if entry.name in _ENTRIES:
        raise ValueError(f"name={entry.name!r}: a policy of that name is registered ({_ENTRIES[entry.name].kind}: "
                         f"{_ENTRIES[entry.name].description}); pick another name, or unregister it first")
    _ENTRIES[entry.name] = entry
    return entry


def unregister(name: str) -> PolicyEntry:
    """Remove the policy ``name`` from the registry (and from every list); returns its entry."""
    try:
        return _ENTRIES.pop(name)
    except KeyError:
        raise ValueError(f"name={name!r}: no policy of that name is registered; registered: "
                         f"{', '.join(_ENTRIES)}") from None


class Names(Sequence[str]):
    """The names of the registered policies whose entry has ``flag`` set, in registration order, then
    ``tail``: read from the registry at each use, so a policy registered later is in it. Equal to the
    tuple of its names; ``names + (...)`` is a view with a longer tail."""

    def __init__(self, flag: Flag, tail: Sequence[str] = ()):
        if flag not in FLAGS:
            raise ValueError(f"flag={flag!r}: must be one of {', '.join(FLAGS)}")
        self.flag, self.tail = flag, tuple(tail)

    def _names(self) -> tuple[str, ...]:
        return (*(name for name, entry in _ENTRIES.items() if getattr(entry, self.flag)), *self.tail)

    @overload
    def __getitem__(self, index: int) -> str: ...

    @overload
    def __getitem__(self, index: slice) -> tuple[str, ...]: ...

    def __getitem__(self, index: int | slice) -> str | tuple[str, ...]:
        return self._names()[index]

    def __len__(self) -> int:
        return len(self._names())

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __contains__(self, name: object) -> bool:
        return name in self._names()

    def __add__(self, other: Sequence[str]) -> Names:
        return Names(self.flag, (*self.tail, *other))

    def __eq__(self, other: Any) -> bool:
        return self._names() == (other._names() if isinstance(other, Names) else other)

    __hash__ = None  # type: ignore[assignment]  # equal to names that change: unhashable, as a list is

    def __repr__(self) -> str:
        return repr(self._names())

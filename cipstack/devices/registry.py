"""The device families this installation knows, found by the ``cipstack.devices`` entry point.

Each entry point of the group names a ``Profile`` (or a callable that returns one), as
``name = "package.module:ATTRIBUTE"``. cipstack's own families register the same way in its
``pyproject.toml``; a family in another distribution needs nothing more than its entry point.

The registry is read once, when a family is first asked for (not when ``cipstack`` is imported: a
one-shot scanner command never reads the installed distributions), in the order found, cipstack's
own families first. A family that cannot be loaded, or whose name another distribution took too,
is kept as a problem: asking for that name raises ``FamilyUnavailable`` naming the distribution,
and every other family still works."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..errors import NotFound

if TYPE_CHECKING:
    from .profiles import Profile

#: The entry point group families register in.
GROUP = "cipstack.devices"
#: The distribution that brings the built-in families.
OWN_DISTRIBUTION = "cipstack"
#: cipstack's own families, as its ``pyproject.toml`` registers them (a test holds the two equal). They are
#: used as they are where the distribution's metadata lacks them: a source tree on ``PYTHONPATH``, or an
#: installation made before they were entry points.
BUILT_IN: tuple[tuple[str, str], ...] = (
    ("acg", "cipstack.devices.acg.family:PROFILE"),
    ("mx2", "cipstack.devices.omron.family:MX2"),
    ("rx", "cipstack.devices.omron.family:RX"),
)


class FamilyUnavailable(NotFound):
    """A family that is installed but cannot be used: its plug-in does not load, or two distributions
    give a family that name."""


@dataclass(frozen=True)
class Registration:
    """One entry point of the group: the family's name, where its ``Profile`` is, who brought it."""

    name: str
    #: ``module:attribute`` (the attribute may be dotted), as an entry point's value.
    value: str
    #: The distribution that declares the entry point.
    distribution: str


def _distribution_name(entry: object) -> str:
    dist = getattr(entry, "dist", None)
    name = getattr(dist, "name", None) if dist is not None else None
    return str(name) if name else "an unknown distribution"


def installed_families() -> list[Registration]:
    """The entry points of ``GROUP`` that the installed distributions declare, cipstack's first (from
    ``BUILT_IN`` where its metadata lacks them), then the others in the order found."""
    from importlib.metadata import entry_points

    found = list(entry_points(group=GROUP))
    own = {entry.name: entry.value for entry in found
           if _distribution_name(entry).lower() == OWN_DISTRIBUTION}
    registrations = [Registration(name, own.pop(name, value), OWN_DISTRIBUTION) for name, value in BUILT_IN]
    registrations += [Registration(name, value, OWN_DISTRIBUTION) for name, value in own.items()]
    registrations += [Registration(entry.name, entry.value, _distribution_name(entry)) for entry in found
                      if _distribution_name(entry).lower() != OWN_DISTRIBUTION]
    return registrations


def load_profile(registration: Registration) -> Profile:
    """The ``Profile`` an entry point names; ``FamilyUnavailable`` naming its distribution when it cannot
    be loaded or is not a profile of that name."""
    from .profiles import Profile

    where = f"device family {registration.name!r} of distribution {registration.distribution} ({registration.value})"
    module_name, _, attribute = registration.value.partition(":")
    try:
        found: object = importlib.import_module(module_name.strip())
        for part in attribute.strip().split(".") if attribute.strip() else ():
            found = getattr(found, part)
        if callable(found) and not isinstance(found, Profile):
            found = found()
    except Exception as exc:  # a plug-in's defect of any kind: reported for that family alone
        raise FamilyUnavailable(f"{where} cannot be loaded: {type(exc).__name__}: {exc}") from None
    if not isinstance(found, Profile):
        raise FamilyUnavailable(f"{where} is a {type(found).__name__}, not a cipstack.devices.profiles.Profile")
    if found.name != registration.name:
        raise FamilyUnavailable(f"{where} declares a profile named {found.name!r}: the entry point's name and the "
                                "profile's must be the same")
    return found


@dataclass(frozen=True)
class _Loaded:
    profiles: dict[str, Profile]
    distributions: dict[str, str]
    problems: dict[str, str]


class FamilyRegistry(Mapping[str, "Profile"]):
    """The families by name, loaded at the first question. Iterating gives the families that work; a name
    whose family does not (``problems``) is still ``in`` the registry, and asking for it raises
    ``FamilyUnavailable`` with the reason."""

    def __init__(self, find: Callable[[], Iterable[Registration]] = installed_families) -> None:
        self._find = find
        self._loaded: _Loaded | None = None

    def _load(self) -> _Loaded:
        if self._loaded is None:
            profiles: dict[str, Profile] = {}
            distributions: dict[str, str] = {}
            problems: dict[str, str] = {}
            for registration in self._find():
                name = registration.name
                if name in distributions:
                    # Two families of one name: neither is chosen behind the user's back.
                    first = distributions[name]
                    profiles.pop(name, None)
                    problems[name] = (f"two distributions give a device family named {name!r}: {first} and "
                                      f"{registration.distribution} (uninstall one)")
                    continue
                distributions[name] = registration.distribution
                try:
                    profiles[name] = load_profile(registration)
                except FamilyUnavailable as exc:
                    problems[name] = str(exc)
            self._loaded = _Loaded(profiles, distributions, problems)
        return self._loaded

    def __getitem__(self, name: str) -> Profile:
        loaded = self._load()
        problem = loaded.problems.get(name)
        if problem is not None:
            raise FamilyUnavailable(problem)
        return loaded.profiles[name]

    def __contains__(self, name: object) -> bool:
        loaded = self._load()
        return name in loaded.profiles or name in loaded.problems

    def __iter__(self) -> Iterator[str]:
        return iter(self._load().profiles)

    def __len__(self) -> int:
        return len(self._load().profiles)

    @property
    def problems(self) -> Mapping[str, str]:
        """The families that cannot be used, by name: why, naming the distribution."""
        return dict(self._load().problems)

    def distribution(self, name: str) -> str:
        """The distribution that brought family ``name``."""
        try:
            return self._load().distributions[name]
        except KeyError:
            raise NotFound(f"no device family {name!r}") from None

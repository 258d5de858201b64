"""The settings a rebake takes: those the last bake was asked, read from its state
(``asked_settings``), and a derived d_max the last bake baked with, kept when an edit moves the
scene's bounds (``kept_d_max``)."""

from __future__ import annotations

from dataclasses import fields

from baker.errors import SettingsError
from baker.rebake import state as state_file
from baker.settings import CALLER_ONLY, Settings


def kept_d_max(stored: dict, settings: Settings, derived: float) -> tuple[float | None, str]:
    """(the d_max a bake keeps from the last bake's, or None; the line that says so) when the
    user gives none and the scene now derives another (``derived``: an edit moved its bounds,
    an object out of the room) than the last bake baked with (its fingerprints ``stored``),
    at the same ``d_max_fraction``: the obscurance distance stays, and with it every texel's
    rays. The kept value is the user's from then on (``Settings.d_max``, recorded as asked in
    the state); --d-max sets another."""
    values = (stored.get("settings") or {}).get("values") or {}
    asked = stored.get("asked") or {}
    last = values.get("d_max")
    if (settings.d_max is not None or not isinstance(last, float) or last == derived
            or asked.get("d_max_fraction") != settings.d_max_fraction):
        return None, ""
    return last, (f"d_max {last:.4g} kept from the last bake (the scene's bounds now derive "
                  f"{derived:.4g}: --d-max {derived:.4g} to take it)")


def asked_settings(path, **overrides) -> Settings:
    """The ``Settings`` the bake that wrote the state at ``path`` was given (for ``baker
    rebake``), with ``overrides``; SettingsError when there is no usable state. The settings
    in ``CALLER_ONLY`` are never taken from the state (it travels with the scene, as untrusted):
    they are the defaults unless ``overrides`` give them."""

    try:
        stored = state_file.load(path, {})
    except state_file.StateUnusable as error:
        raise SettingsError(f"cannot rebake: {error}",
                            fix="run baker bake once (it writes the state), then rebake") from None
    asked = stored.fingerprints.get("asked") if isinstance(stored.fingerprints, dict) else None
    names = {f.name for f in fields(Settings)}
    try:
        values = {k: tuple(v) if isinstance(v, list) else v
                  for k, v in (asked or {}).items() if k in names and k not in CALLER_ONLY}
        Settings(**values).check()
    except (SettingsError, TypeError, ValueError, AttributeError) as error:
        raise SettingsError(f"cannot rebake: the settings stored in the bake state {path} are "
                            f"unusable ({str(error).splitlines()[0]})",
                            fix="bake with `baker bake` and the settings you want") from None
    return Settings(**dict(values, **overrides))

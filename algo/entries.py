"""Rules stored beside a checkpoint's weights as tables of settings (``caution``, ``emergency_braking``)."""

from __future__ import annotations

from typing import TypeVar

Settings = TypeVar("Settings")


def settings_from_entry(source: str, entry: str, settings_class: type[Settings], record) -> Settings:
    """``settings_class(**record)`` for a checkpoint's ``entry`` table; a ValueError naming ``source``
    when the record is not a table, has keys the class lacks, or holds values the class refuses."""
    if not isinstance(record, dict):
        raise ValueError(f"{source}: its {entry} entry is not a table ({record!r})")
    try:
        return settings_class(**record)
    except TypeError as error:
        raise ValueError(f"{source}: its {entry} entry does not match this crossway ({error})") from None
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None

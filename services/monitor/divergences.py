"""The monitor's list of model divergences, manager restarts and violation onsets (docs/semantics.md §7), without I/O.

The step that meets a divergence says so in its :class:`~skinet.wire.messages.LiveState`,
and the next step no longer does; operator views need the whole run's list, and a view
that joins late needs it too.  :class:`DivergenceLog` keeps the last
:data:`~skinet.wire.messages.MAX_DIVERGENCES` entries and the count of older ones, and
packs them as one :class:`~skinet.wire.messages.Divergences` message, which the monitor
publishes on ``skinet/<system>/divergences`` when the list changes and answers on ``get``.

An entry is an event the model could not explain (its step's divergence), or an event
that follows a restart of the skillset's manager (``CanonicalEvent.restart``, set by the
bridge), whether or not the model explains the manager's new state.  A restart event is
noted when it arrives even if it is never applied (it waited while its skillset was
syncing and the resync answer covered it); each event (skillset, source, epoch, seq) is
noted once.  Texts are cut at :data:`MAX_TEXT` characters, so a list holds at most
about 400 000 characters whatever the events carry.  Cost: O(1) per event; each entry is packed
once, so a message joins bytes (O(entries) copies, no validation per publication).
"""

from __future__ import annotations

from collections import OrderedDict, deque

import msgpack

from skinet.wire.messages import MAX_DIVERGENCES, SCHEMA_VERSION, CanonicalEvent, Divergence

REMEMBERED = 1024  # events already noted, kept to note each once
MAX_TEXT = 500  # characters of an entry's event, reason and info (an event may carry 64 KiB of text)


def event_name(ev: CanonicalEvent) -> str:
    """``skillset:transition#seq`` (``status`` for a status-only event), as ``LiveState.event`` names it."""
    return f"{ev.skillset}:{ev.transition or 'status'}#{ev.seq}"


class DivergenceLog:
    """The divergences and manager restarts of one monitor run (not thread-safe: the monitor holds its lock)."""

    def __init__(self, system: str, monitor: str, size: int = MAX_DIVERGENCES):
        self.system, self.monitor = system, monitor
        self.entries: deque[tuple[Divergence, bytes]] = deque(maxlen=size)
        self.total = 0  # entries ever noted
        self._noted: OrderedDict[tuple[str, str, int, int], None] = OrderedDict()
        self._packer = msgpack.Packer(use_bin_type=True)

    @property
    def older(self) -> int:
        """Entries noted and no longer listed."""
        return self.total - len(self.entries)

    def note(self, ev: CanonicalEvent, divergence: str | None, seq: int, stamp: float) -> Divergence | None:
        """Note ``ev`` if the model could not explain it (``divergence``) or it follows a manager restart, and
        it was not noted yet; ``seq`` is the monitor step it made, or the one shown.  Returns the new entry."""
        if divergence is None and not ev.restart:
            return None
        key = (ev.skillset, ev.source, ev.epoch, ev.seq)
        if key in self._noted:
            return None
        self._noted[key] = None
        if len(self._noted) > REMEMBERED:
            self._noted.popitem(last=False)
        return self.add("restart" if ev.restart else "divergence", seq, stamp, ev.skillset, event_name(ev),
                        divergence or "", ev.info)

    def add(self, kind: str, seq: int, stamp: float, skillset: str, event: str, reason: str = "",
            info: str = "") -> Divergence:
        """List one entry as it is (a violation onset: :mod:`services.monitor.violations`)."""
        entry = Divergence(n=self.total, kind=kind, seq=seq, stamp=stamp, skillset=_cut(skillset),  # type: ignore[arg-type]
                           event=_cut(event), reason=_cut(reason), info=_cut(info))
        self.entries.append((entry, self._packer.pack(entry.model_dump(mode="json"))))
        self.total += 1
        return entry

    def payload(self, stamp: float) -> bytes:
        """The :class:`~skinet.wire.messages.Divergences` message of the list now, encoded (the same bytes as
        :func:`skinet.wire.codec.encode` gives)."""
        pack = self._packer.pack
        head = b"".join(pack(k) + pack(v) for k, v in (("v", SCHEMA_VERSION), ("system", self.system),
                                                       ("monitor", self.monitor), ("stamp", stamp),
                                                       ("older", self.older)))
        entries = self._packer.pack_array_header(len(self.entries)) + b"".join(packed for _, packed in self.entries)
        return self._packer.pack_map_header(6) + head + pack("entries") + entries


def _cut(text: str) -> str:
    return text if len(text) <= MAX_TEXT else text[:MAX_TEXT - 1] + "\u2026"

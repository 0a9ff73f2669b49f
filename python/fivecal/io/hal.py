"""The values a HAL file gives a component's pins, read as LinuxCNC's
``halcmd`` reads the file (LinuxCNC 2.9: src/hal/utils/halcmd.c,
halcmd_commands.cc, hal_lib.c; docs/linuxcnc.md, "Reading the old pins").

What halcmd does, and this reader with it:

* A line ending in a backslash continues on the next; ``#`` outside quotes
  starts a comment (so a comment line ending in a backslash swallows the
  next line too); words are separated by blanks, quotes keep blanks in one.
* ``setp PIN VALUE`` and ``PIN = VALUE`` set an unconnected pin; halcmd
  refuses them on a pin linked to a signal.
* ``net SIGNAL PIN...`` (the arrows ``=>``, ``<=``, ``<=>`` are ignored)
  creates the signal if need be and links each pin to it; a pin already on
  another signal is refused. ``linkps PIN SIGNAL``, ``linksp SIGNAL PIN``
  link one pin, ``newsig SIGNAL TYPE`` creates a signal (value 0),
  ``unlinkp`` / ``delsig`` undo a link (the pin keeps the signal's value).
* ``sets SIGNAL VALUE`` sets a signal; halcmd refuses it on a signal that
  does not exist yet or that an output pin drives.
* The first pin linked to a signal that has no pin yet puts its own value
  on the signal (hal_link), so ``setp`` before ``net`` carries over, and a
  ``newsig``/``sets`` value is overwritten by the first input pin linked.
* ``[SECTION]KEY``, ``[SECTION](KEY)``, ``$VAR`` and ``$(VAR)`` are replaced
  from the INI file and the environment, which this reader does not have: a
  pin whose value depends on one gets no value (:attr:`PinValue.problem`
  says so, naming the line).
* ``source FILE`` reads another file (relative to this file's folder, as
  LinuxCNC starts halcmd in the configuration's folder).

A pin of another component on the same signal may be an output that
drives it at run time (``motion.tooloffset.z``); the reader cannot tell an
output from an input, so the value of such a signal is unknown unless a
later ``sets`` (which halcmd accepts only without a driver) sets it.

The text outside comments must be UTF-8 (ASCII, as LinuxCNC writes it);
bytes in comments are not read (halcmd ignores them). Every refusal is a
ValueError ``file:line: ...``.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

from .. import files

_ARROWS = {"=>", "<=", "<=>"}
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\Z")
_BOOL = {"true": 1.0, "false": 0.0}
#: halcmd's commands (halcmd.c, halcmd_commands[]); any other first word is
#: an error unless the line is ``PIN = VALUE``
_COMMANDS = {"addf", "initf", "alias", "delf", "delsig", "debug", "echo", "getp", "gets", "print", "ptype",
             "stype", "help", "linkps", "linksp", "list", "loadrt", "loadusr", "lock", "net", "newsig", "save",
             "setp", "sets", "show", "source", "start", "status", "stop", "unalias", "unecho", "unlinkp",
             "unload", "unloadrt", "unloadusr", "unlock", "waitusr"}
_MAX_SOURCE_DEPTH = 16


@dataclass
class PinValue:
    """What the file makes of one pin: ``value`` (None when the file cannot
    tell) set at ``where`` (``file:line``); ``problem`` says why there is no
    value; ``runtime`` when another pin may drive it while LinuxCNC runs."""

    value: Optional[float]
    where: str
    problem: Optional[str] = None
    runtime: bool = False


@dataclass
class _Signal:
    value: PinValue
    created: str
    pins: List[str] = field(default_factory=list)


def _lines(data: bytes, path: str) -> List[Tuple[int, str]]:
    """(first physical line, code) per logical line, as halcmd_main.c joins
    continuations and strip_comments() cuts comments."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    phys = data.split(b"\n")
    if phys and phys[-1] == b"":
        phys.pop()
    out, buf, start = [], b"", None
    for no, raw in enumerate(phys, 1):
        if raw.endswith(b"\r"):
            raw = raw[:-1]
        start = no if start is None else start
        if raw.endswith(b"\\"):
            buf += raw[:-1]
            if no < len(phys):
                continue
            raw = b""
        buf += raw
        code, quote = bytearray(), None
        for b in buf:
            c = chr(b)
            if quote is None and c == "#":
                break
            if c in "'\"":
                quote = None if quote == c else (c if quote is None else quote)
            code.append(b)
        if quote is not None:
            raise ValueError(f"{path}:{start}: unterminated quoted string (halcmd refuses the line)")
        try:
            text = bytes(code).decode("utf-8")
        except UnicodeDecodeError as e:
            raise ValueError(f"{path}:{start}: not UTF-8 text outside a comment (byte 0x{code[e.start]:02x} at "
                             f"column {e.start + 1}); save the file as UTF-8 or ASCII") from None
        out.append((start, text))
        buf, start = b"", None
    return out


def _tokens(text: str) -> List[str]:
    """Words of a line: blanks separate them, except inside quotes (kept in
    the word, as halcmd keeps them)."""
    out, cur, quote = [], "", None
    for c in text:
        if quote is None and c.isspace():
            if cur:
                out.append(cur)
            cur = ""
            continue
        if c in "'\"":
            quote = None if quote == c else (c if quote is None else quote)
        cur += c
    if cur:
        out.append(cur)
    return out


def _substituted(word: str) -> bool:
    return "$" in word or "[" in word


def parse_number(word: str) -> Optional[float]:
    """A HAL value as a float (decimal notation; TRUE/FALSE for a bit), or None."""
    if _NUMBER.match(word):
        return float(word)
    return _BOOL.get(word.lower())


class _Reader:
    def __init__(self, component: str, component_pins: Sequence[str], wanted: Sequence[str]):
        self.prefix = component + "."
        self.component_pins = list(component_pins)
        self.wanted = {self.prefix + n for n in wanted}
        self.dummy: Dict[str, PinValue] = {}
        self.linked: Dict[str, str] = {}          # pin -> signal
        self.signals: Dict[str, _Signal] = {}
        self.early_sets: Dict[str, str] = {}      # signal -> where a sets came before the signal existed
        self.blind_sets: List[str] = []           # sets on a signal name the file does not spell out

    # -- what a word names ----------------------------------------------------
    def _ours(self, word: str, where: str) -> bool:
        """Whether ``word`` names a pin of the component (refusing a pin it
        does not have, a spelling halcmd would not find, and a name built
        from a substitution that could be one of its pins)."""
        if _substituted(word):
            if self.prefix in word or any(word.endswith("." + p) or word.endswith(")" + p)
                                          for p in self.component_pins):
                raise ValueError(f"{where}: '{word}' names a pin through an INI or environment substitution "
                                 "fivecal cannot resolve; write the pin's name out")
            return False
        if word.lower().startswith(self.prefix.lower()):
            if not word.startswith(self.prefix) or word[len(self.prefix):] not in self.component_pins:
                hint = (" (HAL names are case-sensitive)"
                        if word.lower()[len(self.prefix):] in self.component_pins else "")
                raise ValueError(f"{where}: '{word}' is not a pin of {self.prefix[:-1]}{hint}; its pins are "
                                 f"{', '.join(self.component_pins)}")
            return True
        return False

    def _value(self, word: str, where: str) -> PinValue:
        if _substituted(word):
            return PinValue(None, where, f"its value '{word}' is an INI or environment substitution fivecal "
                                         "cannot resolve; give the number")
        v = parse_number(word)
        if v is None:
            return PinValue(None, where, f"'{word}' is not a number")
        return PinValue(v, where)

    # -- commands ---------------------------------------------------------------
    def _link(self, pin: str, sig: str, where: str) -> None:
        ours = self._ours(pin, where)
        if _substituted(pin) or _substituted(sig):
            if ours or (sig in self.signals and any(p in self.wanted for p in self.signals[sig].pins)):
                raise ValueError(f"{where}: a substitution fivecal cannot resolve in a link of a pin it reads")
            return
        s = self.signals.get(sig)
        old = self.linked.get(pin)
        if old is not None:
            if old != sig and ours:
                raise ValueError(f"{where}: pin {pin} is already linked to signal {old}; halcmd refuses "
                                 "a second signal")
            return
        if s is None:
            if ours:
                raise ValueError(f"{where}: signal {sig} does not exist here; halcmd refuses the link (create "
                                 "it with net or newsig first)")
            return
        if ours and sig in self.early_sets:
            raise ValueError(f"{self.early_sets[sig]}: sets {sig} comes before the signal exists (it is "
                             f"created at {s.created}); halcmd refuses it there: put the sets after the net")
        if not s.pins:
            # hal_link: the first pin on a signal puts its own value on it
            s.value = (self.dummy.get(pin, PinValue(0.0, where)) if ours else
                       PinValue(None, where, f"signal {sig} takes its value from pin {pin} at run time",
                                runtime=True))
        elif not ours:
            # an output pin would drive the signal; only a later sets (refused
            # by halcmd on a driven signal) tells it is not one
            s.value = PinValue(None, where, f"signal {sig} is also on pin {pin}, which may drive it at "
                                            "run time", runtime=True)
        s.pins.append(pin)
        self.linked[pin] = sig

    def _new_signal(self, sig: str, where: str) -> None:
        if sig not in self.signals:
            self.signals[sig] = _Signal(PinValue(0.0, where), where)

    def run(self, path: str, depth: int = 0) -> None:
        if depth > _MAX_SOURCE_DEPTH:
            raise ValueError(f"{path}: sourced more than {_MAX_SOURCE_DEPTH} files deep (a loop?)")
        for no, text in _lines(files.read_bytes(path, "HAL file"), path):
            where = f"{path}:{no}"
            t = _tokens(text)
            if not t:
                continue
            cmd = t[0]
            if cmd == "setp" or (cmd not in _COMMANDS and len(t) == 3 and t[1] == "="):
                if len(t) != 3:
                    if any(self._ours(w, where) for w in t[1:]):
                        raise ValueError(f"{where}: expected 'setp PIN VALUE'")
                    continue
                pin, word = (t[1], t[2]) if cmd == "setp" else (t[0], t[2])
                if not self._ours(pin, where):
                    continue
                if pin in self.linked:
                    sig = self.linked[pin]
                    raise ValueError(f"{where}: setp {pin}: the pin is linked to signal {sig}; halcmd refuses "
                                     f"it (set the signal with 'sets {sig} VALUE')")
                self.dummy[pin] = self._value(word, where)
            elif cmd == "sets":
                if len(t) != 3:
                    continue
                sig, word = t[1], t[2]
                if _substituted(sig):
                    self.blind_sets.append(where)
                elif sig in self.signals:
                    self.signals[sig].value = self._value(word, where)
                else:
                    self.early_sets.setdefault(sig, where)
            elif cmd == "newsig" and len(t) >= 2:
                self._new_signal(t[1], where)
            elif cmd == "net" and len(t) >= 2:
                words = [w for w in t[1:] if w not in _ARROWS]
                sig, pins = words[0], words[1:]
                if self._ours(sig, where):
                    raise ValueError(f"{where}: net {sig}: the first word after 'net' is the signal's name, "
                                     "and this is a pin (halcmd refuses it)")
                if not _substituted(sig):
                    self._new_signal(sig, where)
                for p in pins:
                    self._link(p, sig, where)
            elif cmd in ("linkps", "linksp"):
                words = [w for w in t[1:] if w not in _ARROWS]
                if len(words) == 2:
                    pin, sig = words if cmd == "linkps" else words[::-1]
                    self._link(pin, sig, where)
            elif cmd == "unlinkp" and len(t) == 2:
                self._unlink(t[1])
            elif cmd == "delsig" and len(t) == 2 and t[1] in self.signals:
                for p in list(self.signals[t[1]].pins):
                    self._unlink(p)
                del self.signals[t[1]]
            elif cmd == "source" and len(t) == 2:
                inc = t[1] if os.path.isabs(t[1]) else os.path.join(os.path.dirname(path), t[1])
                self.run(inc, depth + 1)
            elif cmd in ("alias", "unalias") or cmd not in _COMMANDS:
                if any(self._ours(w, where) for w in t):
                    raise ValueError(f"{where}: '{cmd}' on a pin of {self.prefix[:-1]}: fivecal cannot follow "
                                     "what it does to the pin")

    def _unlink(self, pin: str) -> None:
        sig = self.linked.pop(pin, None)
        if sig is not None:
            s = self.signals[sig]
            s.pins.remove(pin)
            self.dummy[pin] = s.value

    def values(self) -> Dict[str, PinValue]:
        out = {}
        for pin in sorted(self.wanted):
            if pin in self.linked:
                v = self.signals[self.linked[pin]].value
                if v.problem is None and self.blind_sets:
                    v = PinValue(None, self.blind_sets[0], "a sets on a signal named through a substitution "
                                                           "fivecal cannot resolve may set it")
            else:
                v = self.dummy.get(pin)
            if v is not None:
                out[pin[len(self.prefix):]] = v
        return out


def pin_values(path: str, component: str, component_pins: Sequence[str],
               wanted: Sequence[str]) -> Dict[str, PinValue]:
    """The values the HAL file ``path`` gives the ``wanted`` pins of
    ``component`` (whose pins are ``component_pins``), by pin name without
    the component; a pin the file never sets or links is left out.
    ValueError (``file:line: ...``) for a line halcmd would refuse that
    touches those pins, a pin name the component does not have, and text
    that is not UTF-8 outside comments."""
    r = _Reader(component, component_pins, wanted)
    r.run(os.fspath(path))
    return r.values()

"""`SweepStore`: a sweep's directory read back (with numpy; lagjax is optional).

Without lagjax the same is a few lines of numpy:

```python
import json, numpy as np
index = json.load(open("out/index.json"))
q = np.concatenate([np.load(f"out/{c['dir']}/q.npy") for c in index["chunks"]])
```
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lagjax._sweep.store import FAILURE_FIELDS, FORMAT, failed_members, read_index


class SweepStore:
    """The chunks of a sweep written by `lj.sweep_to_disk`.

    `index` is `index.json` as a dict: `members`, `chunk_size`, `chunk_count`,
    `complete`, `fingerprint`, `parameters` (shapes and `simulate` options as
    text), `versions`, `fields` (file, one member's shape and dtype), `chunks`
    (the completed ones: directory, member range, failures) and `result_messages`
    (diffrax's message for every `RESULTS` code that occurred).
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        index = read_index(self.path)
        if index is None or index.get("format") != FORMAT:
            raise ValueError(f"{self.path} holds no lagjax sweep (no {FORMAT} index)")
        self.index = index

    @property
    def complete(self) -> bool:
        """Whether every chunk of the sweep is on disk."""
        return bool(self.index["complete"])

    @property
    def fields(self) -> list[str]:
        return list(self.index["fields"])

    def array(self, name: str, *, mmap: bool = False) -> np.ndarray:
        """One field over the completed chunks, in member order (a complete sweep:
        every member). `mmap=True` maps the chunk files instead of reading them,
        but the concatenation still copies; read chunk by chunk for huge sweeps."""
        if name not in self.index["fields"]:
            raise KeyError(f"no field {name!r}; the fields are {self.fields}")
        file = self.index["fields"][name]["file"]
        mode = "r" if mmap else None
        pieces = [
            np.load(self.path / chunk["dir"] / file, mmap_mode=mode, allow_pickle=False)
            for chunk in self.index["chunks"]
        ]
        return np.concatenate(pieces, axis=0)

    def members(self) -> np.ndarray:
        """The member numbers (positions in the batch) of the completed chunks."""
        ranges = [np.arange(c["start"], c["stop"]) for c in self.index["chunks"]]
        return np.concatenate(ranges) if ranges else np.zeros(0, dtype=int)

    def failed(self) -> np.ndarray:
        """True for each member whose `RESULTS` code is a failure or whose state
        (or measured value) stopped being finite
        (`lagjax._sweep.store.failed_members`)."""
        return failed_members(
            {name: self.array(name) for name in FAILURE_FIELDS if name in self.fields}
        )

    def __repr__(self) -> str:
        done = sum(c["stop"] - c["start"] for c in self.index["chunks"])
        return (
            f"SweepStore({str(self.path)!r}, {done}/{self.index['members']} members, "
            f"{sum(c['failed'] for c in self.index['chunks'])} failed)"
        )


def open_sweep(path: str | Path) -> SweepStore:
    """The sweep written to `path` by `lj.sweep_to_disk` (complete or not)."""
    return SweepStore(path)

"""The crack network as OBJ polylines (``cracks.obj``), for inspection in a DCC tool."""

from __future__ import annotations

from pathlib import Path

from crackbake.errors import CrackbakeError
from crackbake.network import CrackNetwork

__all__ = ["write_obj"]


def write_obj(network: CrackNetwork, path: str | Path) -> None:
    """Write the cracks as OBJ polylines for DCC import.

    Each crack becomes ``o crack_<id>`` followed by its ``v`` lines and one ``l`` line through
    all of them (Blender imports it as a chain of edges).  Coordinates use repr precision.

    Parameters
    ----------
    network : CrackNetwork
    path : str or Path
    """
    path = Path(path)
    lines = [
        "# crackbake crack network: one polyline per crack, mesh units",
        f"# cracks {len(network.cracks)}",
    ]
    first = 1  # OBJ indices are 1-based and global over the file
    for c in network.cracks:
        lines.append(f"o crack_{c.id}")
        lines.extend(f"v {x!r} {y!r} {z!r}" for x, y, z in c.points.tolist())
        n = len(c.points)
        if n >= 2:
            lines.append("l " + " ".join(str(i) for i in range(first, first + n)))
        first += n
    try:
        path.write_bytes(("\n".join(lines) + "\n").encode("utf-8"))
    except OSError as exc:
        raise CrackbakeError(
            f"{path}: cannot write the file ({exc.strerror}); "
            "check the folder exists and is writable"
        ) from exc

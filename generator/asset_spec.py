"""The description of one asset instance that layouts place: shared by the layout, the clutter
and the household objects, so that none of them imports another for it."""
from dataclasses import dataclass
from typing import Any, Mapping, Sequence


@dataclass(frozen=True)
class AssetSpec:
    """What the layout needs to know about one asset instance: its class, name and extents."""

    cls: str
    name: str
    asset: str
    params: Mapping[str, Any]
    size: tuple[float, float, float]
    top_z: float | None = None
    top_size: tuple[float, float] | None = None


Catalog = Mapping[str, Sequence[AssetSpec]]

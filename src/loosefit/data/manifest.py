"""Human-readable text of a dataset store's summary (``loosefit info DATA.zarr``)."""

from __future__ import annotations


def _size(num_bytes: int) -> str:
    if num_bytes < 1024:
        return f"{num_bytes} B"
    value = num_bytes / 1024
    for unit in ("KiB", "MiB"):
        if value < 1024:
            return f"{value:.1f} {unit}"
        value /= 1024
    return f"{value:.1f} GiB"


def format_info(info: dict) -> str:
    """Multi-line text of :meth:`loosefit.data.store.DatasetStore.info`'s dict."""
    seqs = info["sequences"]
    lines = [
        f"{info['path']}: {info['format']} v{info['format_version']} "
        f"(created {info['created'] or '?'} by loosefit {info['loosefit_version'] or '?'}), "
        f"{_size(info['size_bytes'])}",
        f"garments ({len(info['garments'])}):",
    ]
    for name, g in info["garments"].items():
        lines.append(f"  {name}: {g['kind']}, {g['verts']} vertices, {g['faces']} faces, {g['pinned']} pinned")
    lines.append(f"bodies ({len(info['bodies'])}):")
    for name, b in info["bodies"].items():
        shape = "?" if b["shape"] is None else ", ".join(f"{v:.3g}" for v in b["shape"])
        lines.append(f"  {name}: {b['model']} [{shape}]")
    lines.append(f"motions ({len(info['motions'])}):")
    for name, m in info["motions"].items():
        lines.append(f"  {name}: {m['frames']} frames at {m['fps']:g} fps, {m['joints']} joints ({m['rig']})")
    lines.append(f"sequences ({seqs['count']}, {seqs['frames']} frames ok):")
    for split, counts in sorted(seqs["by_split"].items()):
        lines.append(f"  {split}: {counts['ok']} ok ({counts['frames']} frames), {counts['failed']} failed")
    refs = info.get("references") or {}
    if refs:
        lines.append(f"reference runs ({len(refs)} sequences; floor: the runs' RMS spread around their mean):")
    for name, r in refs.items():
        if r.get("damaged"):
            lines.append(f"  {name}: damaged (see problems)")
            continue
        floor = "no floor (no run ok)" if r["floor_mm"] is None else f"floor {r['floor_mm']:.2f} mm"
        failed = f", {r['failed']} failed" if r["failed"] else ""
        lines.append(f"  {name}: {r['ok']} ok{failed}, {floor}")
    if info.get("writer"):
        lines.append(f"being written by {info['writer']}")
    if info["problems"]:
        lines.append(f"problems ({len(info['problems'])}):")
        lines.extend(f"  {path}: {problem}" for path, problem in info["problems"].items())
        if any(not path.startswith(".staging") for path in info["problems"]):
            lines.append(f"`loosefit info {info['path']} --repair` drops what is damaged (and only that)")
    else:
        lines.append("problems: none (every chunk read back as written)")
    return "\n".join(lines)


def format_repair(path, dropped: dict[str, str]) -> str:
    """Text of :meth:`loosefit.data.store.DatasetStore.repair`'s result for the store at ``path``."""
    if not dropped:
        return f"{path}: nothing damaged, nothing dropped"
    lines = [f"{path}: dropped {len(dropped)} damaged item(s), kept everything else as it was:"]
    lines.extend(f"  {rel}: {why}" for rel, why in dropped.items())
    kinds = {rel.split("/")[0] for rel in dropped}
    if kinds & {"sequences", "garments", "bodies", "motions"}:
        lines.append(f"`loosefit simulate PLAN --out {path}` (with the plan that made the store) simulates "
                     "the dropped sequences again and adds the dropped garments, bodies and motions back")
    if any(len(rel.split("/")) > 2 or rel.split("/")[0] not in ("sequences", "garments", "bodies", "motions")
           for rel in dropped):
        lines.append(f"`loosefit prepare {path}` writes the dropped prepared data again")
    return "\n".join(lines)

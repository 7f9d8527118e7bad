"""A starting joint map for a skeleton loosefit does not know, from its shape and names.

Both skeletons, the file's and the body rig's, are cut into the same parts by their tree and one
posed frame: the hips (where the legs and the upper body part), two legs, the spine up to the chest
(where the arms part), the neck and head, and two arms. The legs are the two chains below the hips
(the longest path in metres down each), up is from the feet to the hips, the arms are the chains
from the chest towards the two joints farthest out to either side, and the neck is the chest's
remaining chain that reaches highest. Parts are then paired joint by joint:

- legs and arms by their two longest consecutive bones (thigh and shin, upper arm and forearm), which
  fixes every joint of the chain around them (hip socket, ankle, toe, clavicle, hand, fingers);
- the spine and the neck end to end (the chest with the chest), the joints between spread evenly,
  a joint named ``head`` with the rig's head, a chain of one joint with the joint of its name;
- left and right by the names (``Left``, ``L_``, ``_l``... ) and, when the names do not tell, by
  the skeleton's facing (toes point forward; left is up x forward).

Joints left over (twist, share, face, end bones) are listed under ``ignore``. The map is a guess
for the user to check, written as YAML with comments (:func:`joint_map_yaml`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.geometry.lbs import topological_order
from loosefit.geometry.vectors import unit
from loosefit.motion.joint_map import JointMap, resolve_joint_map
from loosefit.motion.rig import TargetRig

# Leaf joints with these name endings mark where a chain ends; they are no joints of their own.
_TIP = re.compile(r"(end|nub|top|tip|site)$")


@dataclass
class SkeletonParts:
    """A skeleton cut into parts, as joint indices.

    Attributes:
        hips: the joint where legs and upper body part.
        legs: ``(left, right)`` chains from below the hips to the toe.
        spine: the chain from above the hips to the chest (the arms' branch joint), chest included.
        neck: the chain above the chest to the top of the head.
        arms: ``(left, right)`` chains from above the chest to the longest finger.
        sides_from_names: whether the names told left from right (else the facing did).
    """

    hips: int
    legs: tuple[list[int], list[int]]
    spine: list[int]
    neck: list[int]
    arms: tuple[list[int], list[int]]
    sides_from_names: bool


def skeleton_parts(names: list[str], parents: np.ndarray, positions: np.ndarray, path: Path | None = None) -> SkeletonParts:
    """Cut a skeleton into :class:`SkeletonParts`.

    Args:
        names: ``J`` joint names.
        parents: ``(J,)`` parent indices, -1 for the root, parents before children.
        positions: ``(J, 3)`` joint positions of one frame in which the skeleton stands (any axes, any unit).
        path: the file, named in errors.

    Raises:
        InputError: a tree without two legs and an upper body, or without two arms.
    """
    parents = np.asarray(parents)
    J = len(names)
    children = [[] for _ in range(J)]
    for j, p in enumerate(parents):
        if p >= 0:
            children[p].append(j)
    size = np.ones(J, int)
    reach = np.zeros(J)  # longest path in length units from a joint down to a leaf
    for j in topological_order(parents)[::-1]:
        for c in children[j]:
            size[j] += size[c]
            reach[j] = max(reach[j], np.linalg.norm(positions[c] - positions[j]) + reach[c])

    def longest(j: int) -> list[int]:
        """``j`` and the joints of the longest path below it."""
        chain = [j]
        while children[chain[-1]]:
            n = chain[-1]
            chain.append(max(children[n], key=lambda c: np.linalg.norm(positions[c] - positions[n]) + reach[c]))
        return chain

    def fail(problem: str) -> InputError:
        return InputError(f"cannot find {problem} in the skeleton: write the joint map by hand "
                          "(see `loosefit motion map --help`)", path)

    hips = 0
    while len(children[hips]) == 1:
        hips = children[hips][0]
    if len(children[hips]) < 2:
        raise fail("the hips (a joint with legs and an upper body below it)")
    upper = max(children[hips], key=lambda c: size[c])
    others = [c for c in children[hips] if c != upper]
    if len(others) == 1:  # the legs hang from a pelvis joint below the hips (Character Creator)
        pelvis = others[0]
        while len(children[pelvis]) == 1:
            pelvis = children[pelvis][0]
        others = children[pelvis]
    if len(others) < 2:
        raise fail("two legs")
    leg_roots = sorted(others, key=lambda c: -reach[c])[:2]
    legs = [_strip_tips(longest(c), names) for c in leg_roots]
    up = unit(positions[hips] - 0.5 * (positions[legs[0][-1]] + positions[legs[1][-1]]))

    # Arms: towards the joints farthest out to either side of the up axis through the hips.
    below_upper = _subtree(upper, children)
    offset = positions[below_upper] - positions[hips]
    lateral = offset - np.outer(offset @ up, up)
    distance = np.linalg.norm(lateral, axis=1)
    first = int(np.argmax(distance))
    opposite = lateral @ lateral[first] < 0
    if not opposite.any():
        raise fail("two arms")
    second = int(np.flatnonzero(opposite)[np.argmax(distance[opposite])])
    tips = (below_upper[first], below_upper[second])
    chest = _common_ancestor(tips[0], tips[1], parents)
    spine = _path(hips, chest, parents)
    arm_roots = [next(c for c in children[chest] if _is_below(t, c, parents)) for t in tips]
    arms = [_strip_tips(longest(c), names) for c in arm_roots]
    rest = [c for c in children[chest] if c not in arm_roots]
    neck = []
    if rest:
        def highest(j):
            return max((positions[k] - positions[chest]) @ up for k in _subtree(j, children))
        j = max(rest, key=highest)
        neck = [j]
        while children[j]:
            j = max(children[j], key=highest)
            neck.append(j)
        neck = _strip_tips(neck, names)

    # Left and right: by the names, else by the facing (toes point forward, left = up x forward).
    legs_side, arms_side = _side(legs, names), _side(arms, names)
    from_names = legs_side != 0 and arms_side != 0
    if not from_names:
        forward = np.zeros(3)
        for leg in legs:
            k = _anchor(leg, positions)
            if k + 2 < len(leg) - 1:  # a toe beyond the ankle
                forward += unit(positions[leg[-1]] - positions[leg[k + 2]])
        forward -= (forward @ up) * up
        if np.linalg.norm(forward) < 1e-6:
            raise fail("which way the skeleton faces (no toes, no left/right in the names)")
        left = np.cross(up, unit(forward))
        def side(pair):  # the chains' mean positions (a hip socket may sit at the pelvis centre)
            return 1 if (positions[pair[0]].mean(0) - positions[pair[1]].mean(0)) @ left > 0 else -1

        legs_side, arms_side = legs_side or side(legs), arms_side or side(arms)
    if legs_side < 0:
        legs = legs[::-1]
    if arms_side < 0:
        arms = arms[::-1]
    return SkeletonParts(hips, (legs[0], legs[1]), spine, neck, (arms[0], arms[1]), from_names)


def suggest_joint_map(
    names: list[str],
    parents: np.ndarray,
    positions: np.ndarray,
    target: TargetRig,
    skip: np.ndarray | None = None,
    name: str = "suggested",
    path: Path | None = None,
) -> tuple[JointMap, SkeletonParts]:
    """A joint map from a source skeleton onto ``target``, by shape and names (see the module doc).

    Args:
        names, parents: the source skeleton (``J`` names, ``(J,)`` parents).
        positions: ``(J, 3)`` source joint positions of one standing frame.
        target: the rig to map onto; its rest pose gives its parts.
        skip: ``(J,)`` bool, entries that are no joints (BVH End Sites); they are left out of the map.
        name: the map's name.

    Returns:
        ``(map, the source's parts)``: every source joint is either mapped or under ``ignore``.
    """
    parents = np.asarray(parents)
    skip = np.zeros(len(names), bool) if skip is None else np.asarray(skip)
    keep = np.flatnonzero(~skip)
    # Joints only: End Sites hang from their joints, never the other way round.
    index = {int(j): k for k, j in enumerate(keep)}
    sub_parents = np.array([index.get(int(parents[j]), -1) if parents[j] >= 0 else -1 for j in keep])
    sub_names = [names[j] for j in keep]
    src = skeleton_parts(sub_names, sub_parents, positions[keep], path)
    tgt = skeleton_parts(target.joint_names, target.parents, target.rest, None)
    pairs: dict[int, int] = {tgt.hips: src.hips}
    for t_chain, s_chain in zip((*tgt.legs, *tgt.arms), (*src.legs, *src.arms)):
        pairs.update(_anchored(t_chain, s_chain, target.rest, positions[keep]))
    pairs.update(_spread(tgt.spine, src.spine, target.joint_names, sub_names))
    pairs.update(_head(tgt.neck, src.neck, target.joint_names, sub_names))
    joints = {target.joint_names[t]: (sub_names[s],) for t, s in sorted(pairs.items())}
    used = set(pairs.values())
    ignore = tuple(n for k, n in enumerate(sub_names) if k not in used)
    return JointMap(name, joints, ignore=ignore, target_rig=target.name), src


def joint_map_yaml(joint_map: JointMap, source: str, parts: SkeletonParts) -> str:
    """The map as YAML (the format of :class:`~loosefit.motion.joint_map.JointMap`), with comments
    saying where it came from and what to check."""
    q = _quote
    lines = [
        f"# Joint map written by `loosefit motion map` from {source}.",
        "# A guess from the skeleton's shape and names: check every line before use (target joint: source joint).",
        "# Left and right were told by the " + ("joint names." if parts.sides_from_names else
                                                 "skeleton's facing (toes forward): the names did not tell."),
        f"name: {q(joint_map.name)}",
        f"target_rig: {q(joint_map.target_rig)}",
        "joints:",
    ]
    lines += [f"  {q(t)}: {q(alts[0])}" for t, alts in joint_map.joints.items()]
    lines.append("# Source joints with no target joint (twist, share, finger, face and end bones):")
    lines.append("ignore:" + ("" if joint_map.ignore else " []"))
    lines += [f"  - {q(n)}" for n in joint_map.ignore]
    lines += ["# Optional keys: calibration (rest | motion), up and front (x, -y, z ...): default detected."]
    return "\n".join(lines) + "\n"


def write_joint_map(bvh_path: str | Path, body, out: str | Path) -> tuple[JointMap, list[str]]:
    """Write a starting joint map for a BVH file's skeleton onto ``body``'s rig to ``out`` (YAML).

    The map is checked against the file as an import would check it (:func:`resolve_joint_map`);
    what does not pass is returned as notes for the user, and the map is written all the same.

    Returns:
        ``(map, notes)``.
    """
    from loosefit.motion.bvh import read_bvh
    from loosefit.paths import atomic_path

    bvh_path = Path(bvh_path)
    bvh = read_bvh(bvh_path)
    positions, _ = bvh.world(slice(0, 1))
    target = TargetRig.from_body(body)
    joint_map, parts = suggest_joint_map(bvh.names, bvh.parents, positions[0], target, bvh.is_end_site(),
                                         name=bvh_path.stem, path=bvh_path)
    notes = []
    try:
        resolve_joint_map(bvh.names, bvh.parents, target, joint_map, bvh_path, skip=bvh.is_end_site())
    except InputError as e:
        notes.append(e.problem)
    missing = [n for n in target.joint_names if n not in joint_map.joints]
    if missing:
        notes.append(f"rig joints with no source joint (they follow their parents): {missing}")
    with atomic_path(out) as tmp:
        tmp.write_text(joint_map_yaml(joint_map, bvh_path.name, parts), encoding="utf-8")
    return joint_map, notes


# ------------------------------------------------------------------------------------------ helpers


def _quote(text: str) -> str:
    """A YAML scalar for a joint name (quoted when YAML would read it otherwise)."""
    return text if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", text) and text.lower() not in (
        "yes", "no", "on", "off", "true", "false", "null", "y", "n") else '"' + text.replace('"', '\\"') + '"'


def _subtree(j: int, children) -> list[int]:
    out, stack = [], [j]
    while stack:
        n = stack.pop()
        out.append(n)
        stack.extend(children[n])
    return out


def _is_below(j: int, ancestor: int, parents) -> bool:
    while j >= 0:
        if j == ancestor:
            return True
        j = parents[j]
    return False


def _common_ancestor(a: int, b: int, parents) -> int:
    above = set()
    while a >= 0:
        above.add(a)
        a = parents[a]
    while b not in above:
        b = parents[b]
    return b


def _path(top: int, bottom: int, parents) -> list[int]:
    """Joints from below ``top`` down to ``bottom`` (included)."""
    out = []
    while bottom != top:
        out.append(bottom)
        bottom = parents[bottom]
    return out[::-1]


def _strip_tips(chain: list[int], names: list[str]) -> list[int]:
    """``chain`` without its trailing end markers (``HeadTop_End``, ``LeftToe_End``...)."""
    while len(chain) > 1 and _TIP.search(re.sub(r"[^a-z]", "", names[chain[-1]].lower())):
        chain = chain[:-1]
    return chain


_LEFT = re.compile(r"(^|[^a-z])(l|left|lft|lf)([^a-z]|$)|left")
_RIGHT = re.compile(r"(^|[^a-z])(r|right|rgt|rt)([^a-z]|$)|right")


def _side_of(name: str) -> int:
    """+1 for a left joint name, -1 for a right one, 0 when the name does not tell."""
    short = name.replace("|", ":").rsplit(":", 1)[-1]
    spaced = re.sub(r"([a-z0-9])([A-Z])", r"\1_\2", short)  # LeftUpLeg -> Left_Up_Leg; LHipJoint stays L_Hip...
    spaced = re.sub(r"^([LR])([A-Z])", r"\1_\2", spaced).lower()
    left, right = bool(_LEFT.search(spaced)), bool(_RIGHT.search(spaced))
    return int(left) - int(right)


def _side(chains, names) -> int:
    """+1 when the names say chains[0] is the left one, -1 when they say it is the right one, else 0."""
    score = [sum(_side_of(names[j]) for j in chain) for chain in chains]
    if score[0] > 0 > score[1]:
        return 1
    if score[0] < 0 < score[1]:
        return -1
    return 0


def _anchor(chain: list[int], positions: np.ndarray) -> int:
    """Index of the joint starting the chain's two longest consecutive bones (thigh + shin, upper arm + forearm)."""
    lengths = np.linalg.norm(np.diff(positions[chain], axis=0), axis=1)
    if len(lengths) < 2:
        return 0
    return int(np.argmax(lengths[:-1] + lengths[1:]))


def _anchored(t_chain, s_chain, t_pos, s_pos) -> dict[int, int]:
    """Pairs of two limb chains aligned on their anchors (:func:`_anchor`)."""
    shift = _anchor(s_chain, s_pos) - _anchor(t_chain, t_pos)
    return {t: s_chain[k + shift] for k, t in enumerate(t_chain) if 0 <= k + shift < len(s_chain)}


def _spread(t_chain, s_chain, t_names, s_names) -> dict[int, int]:
    """Pairs of two chains matched end to end, the joints between spread evenly; a single source
    joint pairs with the target joint of its name, else with the last."""
    nt, ns = len(t_chain), len(s_chain)
    if not nt or not ns:
        return {}
    if ns == 1:
        short = s_names[s_chain[0]].replace("|", ":").rsplit(":", 1)[-1].lower()
        same = [t for t in t_chain if t_names[t].lower() == short]
        return {(same or t_chain)[-1]: s_chain[0]}
    if nt == 1:
        return {t_chain[0]: s_chain[-1]}
    if ns >= nt:
        return {t: s_chain[round(k * (ns - 1) / (nt - 1))] for k, t in enumerate(t_chain)}
    return {t_chain[round(k * (nt - 1) / (ns - 1))]: s for k, s in enumerate(s_chain)}


def _head(t_chain, s_chain, t_names, s_names) -> dict[int, int]:
    """Neck and head: a joint named ``head`` on both sides pairs up and the joints below it spread;
    otherwise the chains spread end to end."""
    def head_at(chain, names):
        return next((k for k, j in enumerate(chain) if "head" in names[j].lower()), None)

    kt, ks = head_at(t_chain, t_names), head_at(s_chain, s_names)
    if kt is None or ks is None:
        return _spread(t_chain, s_chain, t_names, s_names)
    return {t_chain[kt]: s_chain[ks], **_spread(t_chain[:kt], s_chain[:ks], t_names, s_names)}

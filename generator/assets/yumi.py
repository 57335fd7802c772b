"""Procedural ABB YuMi IRB 14000: a torso and two 7-joint arms built as kinematic chains.

Joint order along each arm follows ABB's naming: 1, 2, 7, 3, 4, 5, 6. Joint frames (origin and
fixed rotation of each joint relative to its parent link) and the joint limits are those of the
IRB 14000 (ABB product specification; the same numbers appear in public YuMi URDF descriptions).
The chain is computed in the robot's own frame (x forward, y left, z up, origin at the centre of
the base) and turned by -90 degrees about z at the end so that the robot faces -y.
"""
from __future__ import annotations

import math

import numpy as np

from generator.assets import palette
from generator.assets.builder import (MeshBuilder, check_variant, matrix_from_array, pick, rot_z,
                                      rounded_rect, translate, uniform)

VARIANTS = ('irb14000', 'irb14000_plate')  # on the table itself, or on an aluminium mounting plate
POSES = ('rest', 'work', 'free', 'onearm')
SIDES = ('right', 'left')
JOINTS = ('j1', 'j2', 'j7', 'j3', 'j4', 'j5', 'j6')
JOINT_LIMITS_DEG = {
    'j1': (-168.5, 168.5),
    'j2': (-143.5, 43.5),
    'j7': (-168.5, 168.5),
    'j3': (-123.5, 80.0),
    'j4': (-290.0, 290.0),
    'j5': (-88.0, 138.0),
    'j6': (-229.0, 229.0)
}
JOINT_LIMITS = {
    j: (math.radians(lo), math.radians(hi))
    for j, (lo, hi) in JOINT_LIMITS_DEG.items()
}
# A folded rest pose: elbows low beside the body, grippers in front of it pointing down (right
# arm, in degrees). The left arm mirrors it: joints 1, 7, 4 and 6 change sign, 2, 3 and 5 do not.
REST_DEG = {
    'j1': 88.0,
    'j2': -129.0,
    'j7': -69.0,
    'j3': 76.0,
    'j4': 193.0,
    'j5': 118.0,
    'j6': -115.0
}
MIRRORED = ('j1', 'j7', 'j4', 'j6')
# (xyz, roll-pitch-yaw) of each joint in its parent frame; the shoulder differs per side.
SHOULDER = {
    'right': ((0.05355, -0.0725, 0.41492), (-0.9795, -0.5682, -2.3155)),
    'left': ((0.05355, 0.0725, 0.41492), (0.9781, -0.5716, 2.3180))
}
# yapf: disable
CHAIN = (((0.03, 0.0, 0.1), (math.pi / 2, 0.0, 0.0)),            # joint 2
         ((-0.03, 0.17283, 0.0), (-math.pi / 2, 0.0, 0.0)),      # joint 7
         ((-0.04188, 0.0, 0.07873), (math.pi / 2, -math.pi / 2, 0.0)),  # joint 3
         ((0.0405, 0.16461, 0.0), (-math.pi / 2, 0.0, 0.0)),     # joint 4
         ((-0.027, 0.0, 0.10039), (math.pi / 2, 0.0, 0.0)),      # joint 5
         ((0.027, 0.029, 0.0), (-math.pi / 2, 0.0, 0.0)))        # joint 6
# yapf: enable
LINK_RADII = (0.045, 0.042, 0.04, 0.038, 0.034, 0.03, 0.028)
FLANGE_TO_TIP = 0.15  # flange + servo gripper with fingers
BASE_SIZE = (0.497, 0.399, 0.08)  # robot x (depth) by y (width), plinth height
HEIGHT = 0.571
# torso cross-sections: (z, x_back, x_front, half_width)
TORSO = ((BASE_SIZE[2], -0.22, 0.20, 0.18), (0.30, -0.18, 0.10, 0.14), (0.48, -0.15, 0.045, 0.085),
         (HEIGHT, -0.13, 0.0, 0.06))
MIN_ARM_Z = 0.1  # arms stay above the base plate / the table under the robot
MAX_ARM_Z = 0.8  # working poses: no arm raised far above the head
MAX_REACH_XY = 0.55
MAX_HALF_WIDTH = 0.36  # arms stay within 0.36 m of the robot's mid-plane
MAX_TRIES = 2000
PLATE_COLOR = (182, 184, 188)  # plain aluminium


def _rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _transform(xyz, rpy) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = _rpy(*rpy)
    matrix[:3, 3] = xyz
    return matrix


def _rz(angle: float) -> np.ndarray:
    matrix = np.eye(4)
    c, s = math.cos(angle), math.sin(angle)
    matrix[:2, :2] = [[c, -s], [s, c]]
    return matrix


def arm_frames(side: str, angles: dict[str, float]) -> list[np.ndarray]:
    """Frames (4x4, robot frame) of the 7 links after their joint rotations, then the tool tip."""
    frames = []
    frame = _transform(*SHOULDER[side]) @ _rz(angles['j1'])
    frames.append(frame)
    for joint, (xyz, rpy) in zip(JOINTS[1:], CHAIN):
        frame = frame @ _transform(xyz, rpy) @ _rz(angles[joint])
        frames.append(frame)
    tip = frame.copy()
    tip[:3, 3] = frame[:3, 3] + frame[:3, 2] * FLANGE_TO_TIP
    frames.append(tip)
    return frames


def _arm_samples(frames: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Points along the arm's centre line (from link 2 on) and their link radii."""
    points, radii = [], []
    for k in range(1, len(frames) - 1):
        start, end = frames[k][:3, 3], frames[k + 1][:3, 3]
        for t in np.linspace(0.0, 1.0, 5):
            points.append(start + t * (end - start))
            radii.append(LINK_RADII[min(k, len(LINK_RADII) - 1)])
    return np.array(points), np.array(radii)


def _inside_torso(points: np.ndarray, margin: np.ndarray) -> np.ndarray:
    z = points[:, 2]
    levels = np.array([s[0] for s in TORSO])
    back = np.interp(z, levels, [s[1] for s in TORSO])
    front = np.interp(z, levels, [s[2] for s in TORSO])
    half = np.interp(z, levels, [s[3] for s in TORSO])
    return ((z < HEIGHT + margin) & (points[:, 0] > back - margin) &
            (points[:, 0] < front + margin) & (np.abs(points[:, 1]) < half + margin))


def _arm_check(side: str, angles: dict[str, float]) -> tuple[np.ndarray, np.ndarray] | None:
    """The arm's centre-line samples and radii if the arm alone is valid, else None."""
    for joint, (lo, hi) in JOINT_LIMITS.items():
        if not lo <= angles[joint] <= hi:
            return None
    points, radii = _arm_samples(arm_frames(side, angles))
    if np.any(points[:, 2] - radii < MIN_ARM_Z) or np.any(points[:, 2] > MAX_ARM_Z):
        return None
    if np.any(_inside_torso(points[2:], radii[2:])):
        return None
    if (np.any(np.hypot(points[:, 0], points[:, 1]) > MAX_REACH_XY)
            or np.any(np.abs(points[:, 1]) + radii > MAX_HALF_WIDTH)):
        return None
    return points, radii


def _arms_apart(right: tuple[np.ndarray, np.ndarray], left: tuple[np.ndarray, np.ndarray]) -> bool:
    gaps = np.linalg.norm(right[0][:, None] - left[0][None], axis=2)
    return bool(np.all(gaps > right[1][:, None] + left[1][None] + 0.01))


def pose_is_valid(angles: dict[str, dict[str, float]]) -> bool:
    """Within limits, arms between MIN_ARM_Z and MAX_ARM_Z, out of the torso, within reach and
    apart from each other."""
    arms = [_arm_check(side, angles[side]) for side in SIDES]
    return arms[0] is not None and arms[1] is not None and _arms_apart(*arms)


def _draw_arm(rng: np.random.Generator, side: str, style: str) -> dict[str, float]:
    angles = {}
    for joint in JOINTS:
        lo, hi = JOINT_LIMITS[joint]
        rest = math.radians(REST_DEG[joint])
        if side == 'left' and joint in MIRRORED:
            rest = -rest
        if style == 'rest':
            value = rest + rng.normal(0.0, math.radians(4.0))
        elif style == 'work':
            value = rest + rng.normal(0.0, math.radians(30.0))
        else:
            value = rng.uniform(lo, hi)
        angles[joint] = round(float(np.clip(value, lo, hi)), 4)
    return angles


def _draw_valid_arm(rng: np.random.Generator, side: str, style: str):
    for _ in range(MAX_TRIES):
        angles = _draw_arm(rng, side, style)
        check = _arm_check(side, angles)
        if check is not None:
            return angles, check
    raise RuntimeError(f'no valid YuMi {side} arm pose of style {style!r} in {MAX_TRIES} draws')


def draw_pose(rng: np.random.Generator, style: str) -> dict[str, dict[str, float]]:
    """Joint angles (radians) of both arms: each arm drawn until valid on its own, the pair
    redrawn until the arms keep apart. Style `onearm`: one arm (either side) anywhere within its
    limits, the other folded at rest."""
    styles = {side: style for side in SIDES}
    if style == 'onearm':
        working = pick(rng, SIDES)
        styles = {side: 'free' if side == working else 'rest' for side in SIDES}
    for _ in range(MAX_TRIES):
        (right, right_check), (left, left_check) = (
            _draw_valid_arm(rng, side, styles[side]) for side in SIDES)
        if _arms_apart(right_check, left_check):
            return {'right': right, 'left': left}
    raise RuntimeError(f'no valid YuMi pose of style {style!r} in {MAX_TRIES} draws')


def sample_params(rng: np.random.Generator, index: int) -> tuple[str, dict]:
    """Draw joint angles (radians, within the joint limits) for a valid, collision-free pose;
    pose styles cycle by index, the mounting (variant) every len(POSES) instances."""
    style = POSES[index % len(POSES)]
    variant = VARIANTS[(index // len(POSES)) % len(VARIANTS)]
    angles = draw_pose(rng, style)
    params = {
        'pose': style,
        'joints': angles,
        'gripper_opening': uniform(rng, 0.0, 0.05),
        'body_color': list(pick(rng, palette.ROBOT_BODY)),
        'joint_color': list(pick(rng, palette.ROBOT_JOINT))
    }
    if variant == 'irb14000_plate':  # robot x (depth) by y (width) by thickness, metres
        params['plate'] = [
            uniform(rng, 0.55, 0.65),
            uniform(rng, 0.45, 0.60),
            uniform(rng, 0.012, 0.025)
        ]
    return variant, params


def build(variant: str, params: dict) -> MeshBuilder:
    """Build the robot's mesh from its joint angles."""
    check_variant('yumi', variant, VARIANTS)
    mb = MeshBuilder()
    body, joint = mb.materials(params, body='body_color', joint='joint_color')
    gripper = mb.material('gripper', (45, 45, 48))
    face = rot_z(-math.pi / 2)  # robot x (forward) -> -y
    if variant == 'irb14000_plate':
        plate_depth, plate_width, thickness = params['plate']
        mb.box_between((-plate_depth / 2, -plate_width / 2, 0.0),
                       (plate_depth / 2, plate_width / 2, thickness),
                       mb.material('plate', PLATE_COLOR), face)
        face = translate(0, 0, thickness) @ face
    depth, width, plate = BASE_SIZE
    mb.prism(rounded_rect(depth, width, 0.05), plate, body, face)
    rings = []
    for z, back, front, half in TORSO:
        ring = rounded_rect(front - back, 2 * half, 0.03, z=z)
        rings.append([(x + (front + back) / 2, y, z) for x, y, z in ring])
    mb.loft(rings, body, face)
    for side in SIDES:
        frames = arm_frames(side, params['joints'][side])
        for k, frame in enumerate(frames[:-1]):
            at = face @ matrix_from_array(frame)
            radius = LINK_RADII[k]
            mb.cylinder(radius, 2 * radius, joint, at @ translate(0, 0, -radius), segments=16)
            following = frames[k + 1] if k + 1 < len(frames) - 1 else None
            if following is not None:
                local = np.linalg.solve(frame, following[:, 3])[:3]
                mb.rod((0.0, 0.0, 0.0), tuple(local), radius * 0.85, body, at)
        flange = face @ matrix_from_array(frames[-2])
        mb.cylinder(0.03, 0.03, joint, flange)
        mb.box_between((-0.045, -0.025, 0.03), (0.045, 0.025, 0.11), gripper, flange)
        opening = params['gripper_opening']
        for sign in (-1, 1):
            x = sign * (opening / 2 + 0.008)
            mb.box_between((x - 0.008, -0.01, 0.11), (x + 0.008, 0.01, FLANGE_TO_TIP), gripper,
                           flange)
    return mb

#!/usr/bin/env python3
"""Body measurements of a closed body mesh in garment_sim's frame, as YAML.

    python3 tools/measure_body.py assets/bodies/anny/body.obj [--garmentcode-yaml OUT.yaml]

Frame: metres, Z up, feet on z = 0, body faces -Y, left hand toward +X, A-pose.
Every girth is the perimeter of the convex hull of a plane section (what a
tape measure spans); horizontal sections unless said otherwise. The printed
YAML has
  body:        the GarmentCode body measurement keys (cm, degrees), the same
               keys as GarmentCode's assets/bodies/mean_all.yaml;
  landmarks_m: heights (z, m) and points of the landmarks used;
  extra_cm:    other figures (girth through the bust points, back length, ...);
  method:      for each GarmentCode key, 'measured' or 'estimated' and how.
--garmentcode-yaml writes the `body:` block alone (GarmentCode's body file
format, read by GarmentCode's BodyParametrizationBase).
"""

import argparse
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bodymesh as bm  # noqa: E402

STEP = 0.0025  # m, scan step along heights and along the arm
SHOULDER_ARM_SLOPE_DEG = 30.0  # slope of the top outline that separates shoulder and arm


# ---------------------------------------------------------------- sections

def loops_in_frame(verts, tris, origin, e1, e2, normal, t):
    """Section loops of the plane {p: (p - origin).normal = t}, in (e1, e2)."""
    rel = verts - origin
    local = np.stack([rel @ e1, rel @ e2, rel @ normal], axis=1)
    return bm.slice_loops(local, tris, t)


def vertical_section(verts, tris, x):
    """Loops of the plane x = const, as (y, z) polylines."""
    return bm.slice_loops(verts[:, [1, 2, 0]], tris, x)


def hull_perimeter(loop):
    return bm.polyline_length(bm.convex_hull(loop))


def back_arc(loop):
    """Length of the part of the convex hull of a horizontal section behind
    (+Y) the coronal plane through the section's area centroid: the part of a
    tape between the two balance-line points, measured from the back."""
    h = bm.convex_hull(loop)
    yc = bm.polygon_centroid(loop)[1]
    total = 0.0
    for a, b in zip(h, np.roll(h, -1, axis=0)):
        if a[1] >= yc and b[1] >= yc:
            total += np.linalg.norm(b - a)
        elif (a[1] - yc) * (b[1] - yc) < 0:
            s = (yc - a[1]) / (b[1] - a[1])
            m = a + s * (b - a)
            total += np.linalg.norm((b if b[1] > yc else a) - m)
    return float(total)


def profile_extreme(loop, x_target, side):
    """y of the section boundary at x = x_target on the front (side=-1, most
    negative y) or back (side=+1) of a horizontal section loop."""
    p, q = loop, np.roll(loop, -1, axis=0)
    ys = []
    for a, b in zip(p, q):
        if (a[0] - x_target) * (b[0] - x_target) <= 0 and a[0] != b[0]:
            s = (x_target - a[0]) / (b[0] - a[0])
            ys.append(a[1] + s * (b[1] - a[1]))
    if not ys:
        return None
    return min(ys) if side < 0 else max(ys)


def scan(lo, hi, step=STEP):
    return np.arange(lo, hi + 0.5 * step, step)


# ---------------------------------------------------------------- landmarks

def arm_loops(verts, tris, z, torso):
    """Horizontal section loops at z that are the right arm (+X side, not the
    torso loop)."""
    out = []
    for loop in bm.slice_loops(verts, tris, z):
        if torso is not None and loop is torso:
            continue
        if loop[:, 0].min() > 0.0 and not (loop[:, 0].min() < 0.0 < loop[:, 0].max()):
            out.append(loop)
    return out


def armpit_height(verts, tris, z_from, z_to):
    """Highest z (scanning up from z_from) up to which the arm sections stay
    separate from the torso: above it the arm joins the torso section."""
    seen_arm = False
    prev = None
    for z in scan(z_from, z_to):
        torso = bm.torso_loop(verts, tris, z)
        arms = [lp for lp in arm_loops(verts, tris, z, torso) if bm.polygon_centroid(lp)[0] > torso[:, 0].max()]
        if arms:
            seen_arm = True
            prev = z
        elif seen_arm:
            lo, hi = prev, z
            for _ in range(25):
                mid = 0.5 * (lo + hi)
                t = bm.torso_loop(verts, tris, mid)
                a = [lp for lp in arm_loops(verts, tris, mid, t) if bm.polygon_centroid(lp)[0] > t[:, 0].max()]
                if a:
                    lo = mid
                else:
                    hi = mid
            return lo
    raise RuntimeError("no armpit found")


def torso_top_at(verts, tris, x, z_ref):
    """Top (max z) of the vertical-section loop at plane x that contains the
    torso/arm region at height z_ref; returns (z_top, y_at_top)."""
    best = None
    for loop in vertical_section(verts, tris, x):
        if loop[:, 1].min() <= z_ref <= loop[:, 1].max():
            i = int(np.argmax(loop[:, 1]))
            if best is None or loop[i, 1] > best[0]:
                best = (loop[i, 1], loop[i, 0])
    return best


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("obj")
    ap.add_argument("--garmentcode-yaml", help="also write GarmentCode's body file (body: block) here")
    args = ap.parse_args()

    verts, tris = bm.load_triangles(args.obj)
    z0 = verts[:, 2].min()
    height = verts[:, 2].max() - z0

    crotch_z = bm.crotch_height(verts, tris)
    armpit_z = armpit_height(verts, tris, crotch_z + 0.1, z0 + 0.9 * height)

    # --- torso profile between crotch and armpit
    zs = scan(crotch_z + 0.005, armpit_z - 0.005)
    prof = []
    for z in zs:
        t = bm.torso_loop(verts, tris, z)
        prof.append((z, t, hull_perimeter(t), t[:, 1].min(), t[:, 1].max(), t[:, 0].max()))
    pz = np.array([p[0] for p in prof])
    girth = np.array([p[2] for p in prof])
    front = np.array([p[3] for p in prof])
    back = np.array([p[4] for p in prof])
    half_w = np.array([p[5] for p in prof])

    # hips: level of the most protruding buttocks (max back y) up to 25 cm above the crotch
    m = pz <= crotch_z + 0.25
    i_hip = int(np.argmax(np.where(m, back, -np.inf)))
    hips_z = pz[i_hip]
    # waist: smallest torso girth between 5 cm above the hips and 8 cm below the armpit
    m = (pz >= hips_z + 0.05) & (pz <= armpit_z - 0.08)
    i_waist = int(np.argmin(np.where(m, girth, np.inf)))
    waist_z = pz[i_waist]
    # bust points level: most forward torso point between 5 cm above the waist and the armpit
    m = pz >= waist_z + 0.05
    i_bust = int(np.argmin(np.where(m, front, np.inf)))
    bust_z = pz[i_bust]
    # chest: largest horizontal torso girth from the bust level up to 1 cm below the armpit
    m = (pz >= bust_z) & (pz <= armpit_z - 0.01)
    i_chest = int(np.argmax(np.where(m, girth, -np.inf)))
    chest_z = pz[i_chest]

    bust_loop = prof[i_bust][1]
    # bust points: x of the most forward point of the right half of the bust section
    xs = np.linspace(0.0, bust_loop[:, 0].max() * 0.9, 200)
    yf = np.array([profile_extreme(bust_loop, x, -1) for x in xs])
    x_bp = float(xs[int(np.argmin(yf))])
    bust_points_measured = x_bp >= 0.025
    if not bust_points_measured:
        # no distinct bust points (the most forward point is on the midline):
        # bust-point distance taken as 0.2 x the chest girth
        x_bp = 0.1 * float(girth[i_chest])
    # underbust: most recessed front point (at x = x_bp) up to 12 cm below the bust level
    m = (pz < bust_z - 0.01) & (pz >= bust_z - 0.12)
    fr = np.array([profile_extreme(p[1], max(x_bp, 0.0), -1) if mm else -np.inf for p, mm in zip(prof, m)])
    i_ub = int(np.argmax(fr))
    underbust_measured = pz[i_ub] > bust_z - 0.115
    if not underbust_measured:
        # no recess below the bust: 5 cm below the bust-points level
        i_ub = int(np.argmin(np.abs(pz - (bust_z - 0.05))))
    underbust_z = pz[i_ub]
    # bum points: x of the most backward point of the right half at the hip level
    hip_loop = prof[i_hip][1]
    xs_h = np.linspace(0.0, hip_loop[:, 0].max() * 0.9, 200)
    yb = np.array([profile_extreme(hip_loop, x, +1) for x in xs_h])
    x_bum = float(xs_h[int(np.argmax(yb))])

    # --- neck and shoulders
    ztop = verts[:, 2].max()
    neck_scan = scan(armpit_z + 0.05, armpit_z + 0.5 * (ztop - armpit_z))
    neck_half = [(bm.torso_loop(verts, tris, z)[:, 0].max(), z) for z in neck_scan]
    neck_min_half, neck_min_z = min(neck_half)
    z_ref = armpit_z + 0.01  # vertical sections x = c are one loop through here

    def is_neck(x):
        top = torso_top_at(verts, tris, x, z_ref)
        return top is None or top[0] > neck_min_z

    # where the top of the vertical section x = c drops below the narrowest neck level
    lo, hi = 0.0, 0.5 * verts[:, 0].max()
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if is_neck(mid):
            lo = mid
        else:
            hi = mid
    x_neck = hi
    # top outline of neck, shoulder and arm in the frontal plane, outward from there
    xs_sh = scan(x_neck, verts[:, 0].max(), 0.001)
    tops = []
    for x in xs_sh:
        top = torso_top_at(verts, tris, x, z_ref)
        if top is None:
            break
        tops.append(top)
    xs_sh = xs_sh[:len(tops)]
    tz = np.array([t[0] for t in tops])
    # acromion: walking outward, after the steep neck-to-shoulder part, where the
    # outline (over 5 mm) first slopes down by more than SHOULDER_ARM_SLOPE_DEG
    k_acr = None
    on_shoulder = False
    for k in range(5, len(xs_sh)):
        slope = math.degrees(math.atan2(tz[k - 5] - tz[k], xs_sh[k] - xs_sh[k - 5]))
        if slope <= SHOULDER_ARM_SLOPE_DEG:
            on_shoulder = True
        elif on_shoulder:
            k_acr = k - 5
            break
    if k_acr is None:
        raise RuntimeError("no shoulder/arm transition found")
    x_acr, (z_acr, y_acr) = xs_sh[k_acr], tops[k_acr]
    # side neck point: walking outward from the neck, the first point where the
    # outline (over 2 mm) is no longer steeper than 45 degrees
    k_snp = 0
    for k in range(2, k_acr + 1):
        if math.degrees(math.atan2(tz[k - 2] - tz[k], xs_sh[k] - xs_sh[k - 2])) <= 45.0:
            k_snp = k - 2
            break
    x_snp, (z_snp, y_snp) = xs_sh[k_snp], tops[k_snp]
    nape_z = z_snp
    neck_loop = bm.torso_loop(verts, tris, z_snp + 0.002)

    # --- upper-arm axis from horizontal arm sections just below the armpit
    cents = []
    for z in scan(armpit_z - 0.12, armpit_z - 0.02, 0.005):
        t = bm.torso_loop(verts, tris, z)
        arms = [lp for lp in arm_loops(verts, tris, z, t) if bm.polygon_centroid(lp)[0] > t[:, 0].max()]
        if arms:
            lp = max(arms, key=lambda a: abs(bm.polygon_area(a)))
            c = bm.polygon_centroid(lp)
            cents.append([c[0], c[1], z])
    cents = np.array(cents)
    cm_ = cents.mean(axis=0)
    _, _, vt = np.linalg.svd(cents - cm_)
    d = vt[0] if vt[0][0] > 0 else -vt[0]
    arm_pose_angle = math.degrees(math.atan2(-d[2], d[0]))
    # centreline of the arm: sections perpendicular to the current direction,
    # 1 cm apart, starting from the upper-arm section 2 cm below the armpit
    acr = np.array([x_acr, y_acr, z_acr])
    centre = cents[-1]
    direction = d.copy()
    line = [centre]
    arm_sec = []
    step = 0.01
    offset = step
    while True:
        e1 = np.cross(direction, [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(direction, e1)
        loops = loops_in_frame(verts, tris, centre, e1, e2, direction, offset)
        near = [lp for lp in loops if np.linalg.norm(bm.polygon_centroid(lp)) < 0.05]
        if not near:
            break
        lp = min(near, key=lambda a: np.linalg.norm(bm.polygon_centroid(a)))
        c2 = bm.polygon_centroid(lp)
        new_centre = centre + direction * offset + e1 * c2[0] + e2 * c2[1]
        step_dir = (new_centre - centre) / np.linalg.norm(new_centre - centre)
        direction = 0.5 * direction + 0.5 * step_dir
        direction /= np.linalg.norm(direction)
        centre = new_centre
        line.append(centre)
        arm_sec.append((len(line) - 1, hull_perimeter(lp), centre))
        offset = step
    if len(arm_sec) < 10:
        raise RuntimeError(f"arm centreline too short: {line} {d} {acr}")
    line = np.array(line)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
    total = along[-1]
    # wrist: walking down the arm from a third of the centreline, the smallest
    # girth before the hand (girth back above 1.3 x that minimum)
    best = None
    for sec in arm_sec:
        if along[sec[0]] < total / 3:
            continue
        if best is None or sec[1] < best[1]:
            best = sec
        elif sec[1] > 1.3 * best[1]:
            break
    i_wr, wrist_girth, wrist_centre = best
    # acromion -> wrist along the arm centreline (the first segment starts at the acromion)
    arm_length = float(np.linalg.norm(line[1] - acr) + along[i_wr] - along[1])
    arm_end_to_end = float(np.linalg.norm(wrist_centre - acr))

    # --- thigh
    leg = []
    for z in scan(crotch_z - 0.20, crotch_z - 0.01):
        loops = [lp for lp in bm.slice_loops(verts, tris, z) if bm.polygon_centroid(lp)[0] > 0.0]
        lp = max(loops, key=lambda a: abs(bm.polygon_area(a)))
        leg.append((hull_perimeter(lp), z))
    leg_circ, leg_z = max(leg)

    # --- front tape over the bust at x = x_bp, from the shoulder top down to the waist:
    # front profile y(z) of the horizontal sections at x = x_bp, its convex hull on the front side
    top_here = torso_top_at(verts, tris, x_bp, z_ref)[0]
    fprof = []
    for z in scan(waist_z, top_here - 0.002, 0.002):
        y = profile_extreme(bm.torso_loop(verts, tris, z), x_bp, -1)
        if y is not None:
            fprof.append([y, z])
    fprof = np.array(fprof)
    far = fprof[:, 0].max() + 1.0
    hull = bm.convex_hull(np.vstack([fprof, [[far, fprof[0, 1]], [far, fprof[-1, 1]]]]))
    front_chain = hull[hull[:, 0] < far - 0.5]
    front_chain = front_chain[np.argsort(-front_chain[:, 1])]  # top to bottom
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(front_chain, axis=0), axis=1))])
    to_snp = math.hypot(x_bp - x_snp, front_chain[0, 1] - z_snp)
    waist_over_bust = float(cum[-1]) + to_snp
    bust_line = float(np.interp(-bust_z, -front_chain[:, 1], cum)) + to_snp

    # --- back length along the spine (x = 0), nape to waist, for information
    bprof = []
    for z in scan(waist_z, nape_z, 0.002):
        y = profile_extreme(bm.torso_loop(verts, tris, z), 0.0, +1)
        if y is not None:
            bprof.append([y, z])
    back_length = bm.polyline_length(np.array(bprof), closed=False)

    w_waist = half_w[i_waist]
    w_hip = half_w[i_hip]
    hip_incl = math.degrees(math.atan2(w_hip - w_waist, waist_z - hips_z))
    shoulder_incl = math.degrees(math.atan2(z_snp - z_acr, x_acr - x_snp))

    cm = 100.0
    body = {
        "arm_length": arm_length * cm,
        "arm_pose_angle": arm_pose_angle,
        "armscye_depth": (z_acr - armpit_z) * cm,
        "back_width": back_arc(prof[i_chest][1]) * cm,
        "bum_points": 2 * x_bum * cm,
        "bust": girth[i_chest] * cm,
        "bust_line": bust_line * cm,
        "bust_points": 2 * x_bp * cm,
        "crotch_hip_diff": (hips_z - crotch_z) * cm,
        "head_l": (ztop - nape_z) * cm,
        "height": height * cm,
        "hip_back_width": back_arc(hip_loop) * cm,
        "hip_inclination": hip_incl,
        "hips": girth[i_hip] * cm,
        "hips_line": (waist_z - hips_z) * cm,
        "leg_circ": leg_circ * cm,
        "neck_w": back_arc(neck_loop) * cm,
        "shoulder_incl": shoulder_incl,
        "shoulder_w": 2 * x_acr * cm,
        "underbust": girth[i_ub] * cm,
        "vert_bust_line": (nape_z - bust_z) * cm,
        "waist": girth[i_waist] * cm,
        "waist_back_width": back_arc(prof[i_waist][1]) * cm,
        "waist_line": (nape_z - waist_z) * cm,
        "waist_over_bust_line": waist_over_bust * cm,
        "wrist": wrist_girth * cm,
    }
    landmarks = {
        "floor_z": z0,
        "crotch_z": crotch_z,
        "hip_girth_z": hips_z,
        "waist_girth_z": waist_z,
        "underbust_girth_z": underbust_z,
        "bust_points_z": bust_z,
        "chest_girth_z": chest_z,
        "armpit_z": armpit_z,
        "acromion": [x_acr, y_acr, z_acr],
        "side_neck_point": [x_snp, y_snp, z_snp],
        "nape_z": nape_z,
        "narrowest_neck_z": neck_min_z,
        "top_of_head_z": ztop,
        "wrist_centre": wrist_centre.tolist(),
        "thigh_girth_z": leg_z,
        "upper_arm_axis_direction": d.tolist(),
        "arm_centreline_length_to_fingertip": total,
    }
    extra = {
        "girth_through_bust_points": girth[i_bust] * cm,
        "chest_girth_at_chest_z": girth[i_chest] * cm,
        "largest_torso_girth_crotch_to_waist": float(girth[(pz <= waist_z)].max()) * cm,
        "back_length_nape_to_waist_along_spine": back_length * cm,
        "narrowest_neck_width": 2 * neck_min_half * cm,
        "arm_length_straight_acromion_to_wrist": arm_end_to_end * cm,
        "neck_base_girth": hull_perimeter(neck_loop) * cm,
        "back_width_at_bust_points_level": back_arc(bust_loop) * cm,
    }
    UNDERBUST_METHOD = (
        "measured: torso girth at the most recessed front point (at the bust-point x) within 12 cm below the bust-points level"
        if underbust_measured else
        "estimated: no recess below the bust on this body; torso girth 5 cm below the bust-points level")
    BUST_POINTS_METHOD = (
        "measured: 2 x the x of the most forward point of the right half of the torso section at the bust-points level"
        if bust_points_measured else
        "estimated: no distinct bust points on this body (the most forward point of the bust section is on the midline); 0.2 x the chest girth")
    method = {
        "height": "measured: top of head minus floor",
        "bust": "measured: largest horizontal torso girth (convex hull) from the bust-points level up to 1 cm below the armpit (the chest girth; on this body it exceeds the girth through the bust points, see extra_cm)",
        "underbust": UNDERBUST_METHOD,
        "waist": "measured: smallest horizontal torso girth between 5 cm above the hip line and 8 cm below the armpit",
        "hips": "measured: torso girth at the level of the most protruding buttocks (max back y) within 25 cm above the crotch",
        "leg_circ": "measured: largest one-thigh girth from 20 cm to 1 cm below the crotch",
        "wrist": "measured: smallest girth of the sections perpendicular to the arm centreline before the hand (walking down the arm from a third of the centreline, until the girth exceeds 1.3 x the running minimum)",
        "waist_back_width": "measured: part of the waist girth hull behind the coronal plane through the section centroid",
        "back_width": "measured: part of the chest girth hull behind the coronal plane through the section centroid",
        "hip_back_width": "measured: part of the hip girth hull behind the coronal plane through the section centroid",
        "neck_w": "estimated: part of the hull of the horizontal neck section 2 mm above the side neck point behind the coronal plane through its centroid",
        "waist_line": "measured vertically: nape level minus waist level (GarmentCode derives its waist level as height - head_l - waist_line, so this places garments at the measured waist; the length along the spine is in extra_cm)",
        "waist_over_bust_line": "estimated: straight side-neck-point-to-profile segment plus the front convex-hull tape of the section x = bust point, from the shoulder top to the waist level",
        "bust_line": "estimated: the same tape from the side neck point down to the bust-points level",
        "arm_length": "measured: acromion to the upper-arm section centre 2 cm below the armpit (straight), then along the arm centreline (sections 1 cm apart, perpendicular to the arm) to the wrist section centre; the straight acromion-wrist distance is in extra_cm",
        "head_l": "estimated: top of head minus the nape level, the nape level taken as the height of the side neck point (first point of the frontal top outline, walking outward from the neck, that is not steeper than 45 degrees)",
        "shoulder_w": "measured: 2 x the acromion x; acromion = where the top outline of the shoulder (vertical sections x = const) first slopes down by more than 30 degrees (arm)",
        "armscye_depth": "measured vertically: acromion height minus armpit height (arm section joins the torso)",
        "bust_points": BUST_POINTS_METHOD,
        "hips_line": "measured vertically: waist level minus hip level",
        "bum_points": "measured: 2 x the x of the most backward point of the right half of the hip section",
        "crotch_hip_diff": "measured vertically: hip level minus crotch level (lowest level where one section spans x = 0)",
        "vert_bust_line": "measured vertically: nape level minus bust-points level",
        "hip_inclination": "measured: angle from vertical of the side line from the waist side point to the hip side point (max x of the sections)",
        "shoulder_incl": "measured: angle below horizontal of the line from the side neck point to the acromion (frontal plane)",
        "arm_pose_angle": "measured: angle below horizontal of the right arm axis (principal axis of the centroids of horizontal upper-arm sections from 12 cm to 2 cm below the armpit), projected on the frontal plane",
    }

    def r(v, nd):
        if isinstance(v, (list, tuple)):
            return [r(x, nd) for x in v]
        return round(float(v), nd)

    lines = ["# tools/measure_body.py " + os.path.basename(args.obj),
             "# body: GarmentCode keys, cm and degrees; landmarks_m: metres, garment_sim frame", "body:"]
    for k in sorted(body):
        lines.append(f"  {k}: {r(body[k], 3)}")
    lines.append("landmarks_m:")
    for k, v in landmarks.items():
        lines.append(f"  {k}: {r(v, 4)}")
    lines.append("extra_cm:")
    for k, v in extra.items():
        lines.append(f"  {k}: {r(v, 3)}")
    lines.append("method:")
    for k in sorted(method):
        lines.append(f"  {k}: \"{method[k]}\"")
    print("\n".join(lines))

    if args.garmentcode_yaml:
        with open(args.garmentcode_yaml, "w", encoding="utf-8") as f:
            f.write(f"# GarmentCode body measurements of {args.obj} (cm, degrees),\n")
            f.write(f"# written by: python3 tools/measure_body.py {args.obj} "
                    f"--garmentcode-yaml {args.garmentcode_yaml}\n")
            f.write("body:\n")
            for k in sorted(body):
                f.write(f"  {k}: {r(body[k], 3)}\n")


if __name__ == "__main__":
    main()

import {
  AXES,
  round,
  type Action,
  type Axis,
  type AxisVec,
  type GError,
  type InterpEnv,
  type Model,
} from './model';

/**
 * Moves as the simulated g2core plans them: straight moves checked against the soft limits and
 * timed at the feed (or the axes' maximum velocities for a rapid), and arcs cut into chords of
 * such moves. Used by the interpreter (gcode.ts). Everything here is simulated.
 */

/**
 * G2/G3 in the selected plane (G17 XY, G18 XZ, G19 YZ, the firmware's axis order) with the
 * third linear axis moving along (helix): centre from I/J/K (incremental with G91.1, absolute
 * with G90.1) or from R, then cut into chords of about 2 mm, each a move at the feed. Errors
 * are the firmware's arc codes (153-159); a chord past a soft limit is 233 (soft limit during arc).
 */
export function arc(
  m: Model,
  env: InterpEnv,
  to: AxisVec,
  o: { co: AxisVec; g92: AxisVec; scale: number; other: Record<string, number>; cw: boolean },
  actions: Action[],
): { model: Model; actions: Action[] } | { error: GError } {
  const planes: [Axis, Axis, Axis, string, string][] = [
    ['x', 'y', 'z', 'I', 'J'],
    ['x', 'z', 'y', 'I', 'K'],
    ['y', 'z', 'x', 'J', 'K'],
  ];
  const [p, q, lin, wp, wq] = planes[m.plan] ?? planes[0]!;
  const start = { ...m.pos };
  const dp = to[p] - start[p];
  const dq = to[q] - start[q];
  const closed = Math.abs(dp) < 1e-9 && Math.abs(dq) < 1e-9;
  let cp: number;
  let cq: number;
  const r = o.other.R;
  if (r !== undefined) {
    if (closed) return { error: { code: 159, additional: 'an R arc needs an end point' } };
    const radius = r * o.scale;
    const disc = 4 * radius * radius - dp * dp - dq * dq;
    if (disc < -1e-6) return { error: { code: 154, additional: `R${r} is shorter than half the chord` } };
    let h = -Math.sqrt(Math.max(0, disc)) / Math.hypot(dp, dq);
    if (!o.cw) h = -h;
    if (radius < 0) h = -h;
    cp = start[p] + 0.5 * (dp - dq * h);
    cq = start[q] + 0.5 * (dq + dp * h);
  } else {
    const ip = o.other[wp];
    const iq = o.other[wq];
    if (ip === undefined && iq === undefined)
      return { error: { code: 157, additional: `${wp}/${wq} for the selected plane` } };
    if (m.admo === 0) {
      cp = (ip ?? 0) * o.scale + o.co[p] + o.g92[p];
      cq = (iq ?? 0) * o.scale + o.co[q] + o.g92[q];
    } else {
      cp = start[p] + (ip ?? 0) * o.scale;
      cq = start[q] + (iq ?? 0) * o.scale;
    }
  }
  const r0 = Math.hypot(start[p] - cp, start[q] - cq);
  const r1 = Math.hypot(to[p] - cp, to[q] - cq);
  if (r0 < 1e-6) return { error: { code: 154, additional: 'the centre is the start point' } };
  if (Math.abs(r0 - r1) > Math.max(0.05, 0.001 * r0))
    return { error: { code: 158, additional: `start radius ${round(r0)} ≠ end radius ${round(r1)}` } };
  const a0 = Math.atan2(start[q] - cq, start[p] - cp);
  const a1 = Math.atan2(to[q] - cq, to[p] - cp);
  let sweep = a1 - a0;
  if (closed) sweep = o.cw ? -2 * Math.PI : 2 * Math.PI;
  else if (o.cw && sweep >= 0) sweep -= 2 * Math.PI;
  else if (!o.cw && sweep <= 0) sweep += 2 * Math.PI;
  const n = Math.min(360, Math.max(4, Math.ceil((Math.abs(sweep) * r0) / 2)));
  let cur: Model = m;
  for (let k = 1; k <= n; k++) {
    const f = k / n;
    const point: AxisVec =
      k === n
        ? { ...to }
        : {
            ...to,
            [p]: cp + r0 * Math.cos(a0 + sweep * f),
            [q]: cq + r0 * Math.sin(a0 + sweep * f),
            [lin]: start[lin] + (to[lin] - start[lin]) * f,
          };
    const r2 = move(cur, env, point, false, actions);
    if ('error' in r2) {
      const soft = r2.error.code >= 221 && r2.error.code <= 232;
      return soft ? { error: { code: 233, additional: r2.error.additional } } : r2;
    }
    cur = r2.model;
  }
  return { model: cur, actions };
}

export function move(
  m: Model,
  env: InterpEnv,
  to: AxisVec,
  rapid: boolean,
  actions: Action[],
): { model: Model; actions: Action[] } | { error: GError } {
  // Soft limits (sl=1) apply to homed axes with distinct travel min and max, as in the firmware.
  if (env.softLimits) {
    for (const [i, a] of AXES.entries()) {
      const ax = env.axis(a);
      if (!m.homed[a] || ax.tn === ax.tm || to[a] === m.pos[a]) continue;
      if (to[a] < ax.tn)
        return { error: { code: 221 + i * 2, additional: `${a.toUpperCase()} ${round(to[a])} < ${ax.tn}` } };
      if (to[a] > ax.tm)
        return { error: { code: 222 + i * 2, additional: `${a.toUpperCase()} ${round(to[a])} > ${ax.tm}` } };
    }
  }
  let dist2 = 0;
  let minMs = 0;
  for (const a of AXES) {
    const d = Math.abs(to[a] - m.pos[a]);
    if (d === 0) continue;
    dist2 += d * d;
    const ax = env.axis(a);
    const limit = rapid ? ax.vm : ax.fr;
    if (limit > 0) minMs = Math.max(minMs, (d / limit) * 60_000);
  }
  const dist = Math.sqrt(dist2);
  let ms = minMs;
  let rate = 0;
  if (!rapid) {
    if (m.feed <= 0) return { error: { code: 142, additional: 'G1/G2/G3 need an F word' } };
    const feedMs = m.frmo === 0 ? 60_000 / m.feed : (dist / (m.feed * env.feedOverride)) * 60_000;
    ms = Math.max(ms, feedMs);
  }
  rate = ms > 0 ? (dist / ms) * 60_000 : 0;
  if (dist > 0) actions.push({ t: 'move', to, ms, rate });
  m.pos = to;
  return { model: m, actions };
}

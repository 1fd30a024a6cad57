import { interpret } from './gcode';
import { AXES, type Axis } from './model';
import { G2coreOperations } from './operations';
import type { HomeLeg, Op, Running, SimAction } from './state';

/**
 * Time and motion of the simulated g2core: each tick interprets the running operation's next
 * line (gcode.ts) and plays its actions out at their rates: moves interpolated at the feed,
 * homing legs searching for their switch, dwells, JSON lines. The fourth layer of the simulator.
 */
export abstract class G2coreMotion extends G2coreOperations {
  override tick(): void {
    const t = this.now();
    let budget = Math.max(0, t - this.last);
    this.last = t;
    if (this.demo && !this.ticking) {
      this.ticking = true;
      try {
        this.demoStep();
      } finally {
        this.ticking = false;
      }
    }
    if (this.alarmed() !== null || this.stat === 6 || this.stat === 11) {
      this.vel = 0;
      return;
    }
    let guard = 0;
    while (guard++ < 2000) {
      if (!this.running) {
        const action = this.pending.shift();
        if (action) {
          this.begin(action);
          continue;
        }
        const op = this.currentOp();
        if (!op) {
          if (this.busy()) this.stat = this.ended ? 4 : 3;
          this.vel = 0;
          return;
        }
        this.step(op);
        continue;
      }
      if (budget <= 0) return;
      const r = this.running;
      const use = Math.min(budget, r.ms - r.elapsed);
      budget -= use;
      r.elapsed += use;
      const f = r.ms > 0 ? Math.min(1, r.elapsed / r.ms) : 1;
      if (r.action.t === 'move' || r.action.t === 'homeleg') {
        for (const a of AXES) this.mpos[a] = r.from[a] + (r.to[a] - r.from[a]) * f;
        this.vel = r.rate;
      } else this.vel = 0;
      if (r.elapsed >= r.ms) this.finish(r);
    }
  }

  /** Interpret the next line of the running operation. */
  private step(op: Op): void {
    if (op.state === 'pend') {
      op.state = 'run';
      const job = op.jobId !== null ? this.jobs.get(op.jobId) : undefined;
      if (job) {
        job.state = 'running';
        job.started = this.now();
      }
    }
    if (op.next >= op.lines.length) {
      this.finishOp(op, null);
      return;
    }
    const text = op.lines[op.next]!;
    op.next++;
    const r = interpret(this.model, this.env(false), text);
    if ('error' in r) {
      this.finishOp(op, r.error);
      // Soft limits in a running program alarm the machine, as the firmware does.
      if (r.error.code >= 220 && r.error.code <= 233) this.stat = 2;
      return;
    }
    this.model = r.model;
    this.line = r.model.lineNo ?? this.line + 1;
    if (r.actions.length === 0) {
      op.done++;
      if (this.stat !== 9 && this.stat !== 6) this.stat = 5;
      return;
    }
    this.pending.push(...r.actions, { t: 'dwell', ms: -1 } /* marks the end of the line */);
  }

  private begin(action: SimAction): void {
    const op = this.currentOp();
    if (action.t === 'dwell' && action.ms < 0) {
      if (op) op.done++;
      return;
    }
    const from = { ...this.mpos };
    if (action.t === 'move') {
      this.stat = 5;
      this.running = {
        action,
        elapsed: 0,
        from,
        to: action.to,
        ms: action.ms,
        rate: action.rate / this.unitScale(),
      };
    } else if (action.t === 'dwell') {
      this.stat = 5;
      this.running = { action, elapsed: 0, from, to: from, ms: action.ms, rate: 0 };
    } else if (action.t === 'home') {
      this.stat = 9;
      this.pending.unshift(...this.homeLegs(action.axes));
    } else if (action.t === 'homeleg') {
      this.stat = 9;
      const to = { ...from, [action.axis]: action.to };
      const ms = (Math.abs(action.to - from[action.axis]) / Math.max(1, action.rate)) * 60_000;
      this.running = { action, elapsed: 0, from, to, ms, rate: action.rate };
    } else if (action.t === 'end') {
      this.ended = true;
    } else if (action.t === 'json') {
      // Like the firmware's {"r":{…}}: null reads, a value sets and echoes what is now set.
      const reply: Record<string, unknown> = {};
      for (const [k, v] of Object.entries(action.values)) {
        try {
          if (v !== null) this.applySet(k, v);
          reply[k] = this.readValue(k);
        } catch {
          reply[k] = null;
        }
      }
      if (op) op.replies.push(reply);
    }
  }

  private finish(r: Running): void {
    this.running = null;
    this.vel = 0;
    if (r.action.t === 'homeleg' && r.action.home !== null) {
      const a = r.action.axis;
      this.mpos[a] = r.action.home;
      this.model.pos[a] = r.action.home;
      this.drift[a] = 0;
      if (!this.pending.some((p) => p.t === 'homeleg')) this.stat = 5;
    }
  }

  /**
   * The legs of a homing cycle. The switch sits zb + 1 mm beyond the home position, so that after
   * search, latch and zero backoff the axis stands exactly at home. Until then the simulator
   * knows where the axis physically is (position + drift); the controller does not.
   */
  private homeLegs(axes: Axis[]): HomeLeg[] {
    const legs: HomeLeg[] = [];
    const pos = { ...this.mpos };
    for (const a of axes) {
      const toMax = this.num(a, 'hd') === 1;
      const dir = toMax ? 1 : -1;
      const home = toMax ? this.num(a, 'tm') : this.num(a, 'tn');
      const latch = Math.min(1, Math.max(0.1, this.num(a, 'lb') || 1));
      const zb = Math.max(0, this.num(a, 'zb'));
      const sv = Math.max(1, this.num(a, 'sv'));
      const lv = Math.max(1, this.num(a, 'lv'));
      const switchAt = home + dir * (zb + latch); // physical
      const atSwitch = pos[a] + (switchAt - (pos[a] + this.drift[a]));
      legs.push(
        { t: 'homeleg', axis: a, phase: 'search', to: atSwitch, rate: sv, home: null },
        { t: 'homeleg', axis: a, phase: 'latch', to: atSwitch - dir * latch, rate: lv, home: null },
        { t: 'homeleg', axis: a, phase: 'backoff', to: atSwitch - dir * (latch + zb), rate: sv, home },
      );
      pos[a] = home;
    }
    return legs;
  }
}

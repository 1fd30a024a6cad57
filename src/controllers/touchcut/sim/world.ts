import type { SimOptions } from '../../../fleet/sim';
import { PROGRAM_NAMES } from './statsgen';

/** The simulated table: a cutting program moving along a path, the operator, faults, the demo. */

export const TABLE = { w: 3000, h: 1500 };
export const FEED_MM_S = 40; // 2400 mm/min
export const RAPID_MM_S = 300;
const PIERCE_S = 1.5;
const AUTO_START_S = 8;

export interface Segment {
  kind: 'rapid' | 'pierce' | 'cut';
  from: [number, number];
  to: [number, number];
  dur: number;
}

/** Nest size of a program: 3×2 parts (about 3 minutes), or 4×3 for the demo job (about 6). */
function buildProgram(seed: number, nest: { cols: number; rows: number } = { cols: 3, rows: 2 }): Segment[] {
  const segs: Segment[] = [];
  let at: [number, number] = [0, 0];
  const { cols, rows } = nest;
  const w = 280 + (seed % 3) * 40;
  const h = 180 + (seed % 2) * 60;
  for (let r = 0; r < rows; r++) {
    for (let c = 0; c < cols; c++) {
      const x = 200 + c * (w + 150);
      const y = 200 + r * (h + 150);
      const start: [number, number] = [x, y];
      segs.push({ kind: 'rapid', from: at, to: start, dur: Math.hypot(x - at[0], y - at[1]) / RAPID_MM_S });
      segs.push({ kind: 'pierce', from: start, to: start, dur: PIERCE_S });
      const pts: Array<[number, number]> = [
        [x + w, y],
        [x + w, y + h],
        [x, y + h],
        [x, y],
      ];
      let p = start;
      for (const q of pts) {
        segs.push({ kind: 'cut', from: p, to: q, dur: Math.hypot(q[0] - p[0], q[1] - p[1]) / FEED_MM_S });
        p = q;
      }
      at = start;
    }
  }
  segs.push({ kind: 'rapid', from: at, to: [0, 0], dur: Math.hypot(at[0], at[1]) / RAPID_MM_S });
  return segs;
}

export type Mode = 'idle' | 'running' | 'paused' | 'error' | 'complete';

export interface LiveTotals {
  time: number;
  distance: number;
  starts: number;
  errors: number;
}

export abstract class TouchcutSimWorld {
  autoOperator = true;
  /**
   * Demo job (control `demo`): larger nests (12 parts, about six minutes at 100 % feed) that the
   * simulated operator restarts a few seconds after each one completes. Only the simulator's own
   * state changes: no request is sent, exactly like an operator pressing Start at the machine.
   */
  demoJob = false;
  mode: Mode = 'idle';
  programName = 'No Active Program';
  protected program: Segment[] = [];
  protected segIndex = 0;
  protected segT = 0;
  protected programCount = 0;
  protected idleFor = 0;
  protected feedOverride = 100;
  pos = { x: 0, y: 0, z: 25 };
  toolOn = false;
  protected errorMsg: { key: string; msg: string } | null = null;
  protected lastAdvance: number;
  /** Live accumulation since the simulator started, added to the machine totals. */
  readonly live: LiveTotals = { time: 0, distance: 0, starts: 0, errors: 0 };
  /** Unloader: parts dropped on pallet stations. */
  protected unloaded: Array<{ time: number; program: string; part: number; station: number }> = [];
  protected readonly now: () => number;
  protected readonly name: string;

  constructor(opts: SimOptions) {
    this.now = opts.now ?? Date.now;
    this.name = opts.name;
    this.lastAdvance = this.now();
  }

  // ---- world ------------------------------------------------------------------------------

  startProgram(): void {
    this.advance();
    if (this.mode === 'running' || this.mode === 'paused' || this.mode === 'error') return;
    this.programCount++;
    this.program = buildProgram(this.programCount, this.demoJob ? { cols: 4, rows: 3 } : undefined);
    this.programName = `${PROGRAM_NAMES[this.programCount % PROGRAM_NAMES.length] ?? 'PART'}.nc`;
    this.segIndex = 0;
    this.segT = 0;
    this.mode = 'running';
  }

  pause(): void {
    this.advance();
    if (this.mode === 'running') {
      this.mode = 'paused';
      this.toolOn = false;
    }
  }

  resume(): void {
    this.advance();
    if (this.mode === 'paused') this.mode = 'running';
  }

  stop(): void {
    this.advance();
    if (this.mode === 'running' || this.mode === 'paused') {
      this.mode = 'idle';
      this.toolOn = false;
      this.idleFor = 0;
    }
  }

  fault(key = 'TorchCollision', msg = 'Torch collision detected'): void {
    this.advance();
    this.mode = 'error';
    this.toolOn = false;
    this.errorMsg = { key, msg };
    this.live.errors++;
  }

  clearFault(): void {
    this.advance();
    if (this.mode === 'error') {
      this.mode = 'paused';
      this.errorMsg = null;
    }
  }

  get progress(): number {
    if (this.mode === 'complete') return 100;
    if (this.program.length === 0 || this.mode === 'idle') return 0;
    const total = this.program.reduce((s, g) => s + g.dur, 0);
    const done = this.program.slice(0, this.segIndex).reduce((s, g) => s + g.dur, 0) + this.segT;
    return Math.min(100, (done / total) * 100);
  }

  get segment(): Segment | null {
    return this.mode === 'running' || this.mode === 'paused' || this.mode === 'error'
      ? (this.program[this.segIndex] ?? null)
      : null;
  }

  /** Moves the world to now. */
  advance(): void {
    const t = this.now();
    let dt = Math.max(0, (t - this.lastAdvance) / 1000);
    this.lastAdvance = t;
    if (this.mode !== 'running') {
      if ((this.mode === 'idle' || this.mode === 'complete') && this.autoOperator) {
        this.idleFor += dt;
        if (this.idleFor >= AUTO_START_S) {
          this.idleFor = 0;
          this.startProgram();
        }
      }
      return;
    }
    dt *= this.feedOverride / 100;
    while (dt > 0 && this.mode === 'running') {
      const seg = this.program[this.segIndex];
      if (!seg) {
        this.mode = 'complete';
        this.toolOn = false;
        this.idleFor = 0;
        this.pos = { x: 0, y: 0, z: 25 };
        return;
      }
      const left = seg.dur - this.segT;
      const step = Math.min(left, dt);
      if (seg.kind === 'pierce' && this.segT === 0 && step > 0) this.live.starts++;
      this.segT += step;
      dt -= step;
      const f = seg.dur > 0 ? this.segT / seg.dur : 1;
      this.pos.x = seg.from[0] + (seg.to[0] - seg.from[0]) * f;
      this.pos.y = seg.from[1] + (seg.to[1] - seg.from[1]) * f;
      this.pos.z = seg.kind === 'rapid' ? 25 : seg.kind === 'pierce' ? 4 : 1.5;
      this.toolOn = seg.kind !== 'rapid';
      if (seg.kind !== 'rapid') this.live.time += step;
      if (seg.kind === 'cut') this.live.distance += step * FEED_MM_S;
      if (this.segT >= seg.dur) {
        // A part is finished when its last contour side is done.
        const next = this.program[this.segIndex + 1];
        if (seg.kind === 'cut' && next && next.kind !== 'cut') {
          this.unloaded.push({
            time: this.now(),
            program: this.programName,
            part: this.unloaded.filter((u) => u.program === this.programName).length + 1,
            station: 1 + (this.unloaded.length % 2),
          });
          if (this.unloaded.length > 500) this.unloaded.shift();
        }
        this.segIndex++;
        this.segT = 0;
      }
    }
  }

  /**
   * Starts the demo job: a cutting program that runs for several minutes and, once complete, starts
   * again (automatic cycle start on). A held or faulted program is stopped and replaced; a running
   * one is left alone (the next cycles are demo-sized).
   */
  startDemo(): void {
    this.advance();
    this.demoJob = true;
    this.autoOperator = true;
    this.feedOverride = 100;
    if (this.mode === 'error') {
      this.errorMsg = null;
      this.mode = 'paused';
    }
    if (this.mode === 'paused') this.stop();
    if (this.mode !== 'running') this.startProgram();
  }
}

import { jsonResponse } from '../../../fleet/sim';
import { statusText } from '../codes';
import { G2Fail, isRecord } from './fail';
import { interpret } from './gcode';
import { cloneModel, type GError } from './model';
import { G2coreSettings } from './settings';
import type { Op, SimJob } from './state';

/**
 * Operations of the simulated g2core: the queue of `run` and `sendfile` operations, how one ends
 * (done, error, kill, alarm) and what a client sees of it. The third layer of the simulator; the
 * lines themselves run in motion.ts.
 */
export abstract class G2coreOperations extends G2coreSettings {
  protected addOp(
    optype: 'run' | 'sendfile',
    value: string[] | string,
    lines: string[],
    jobId: number | null,
  ): Op {
    const op: Op = {
      id: ++this.opSeq,
      optype,
      value,
      lines,
      next: 0,
      done: 0,
      state: 'pend',
      error: null,
      jobId,
      replies: [],
    };
    this.ops.set(op.id, op);
    if (this.ops.size > 200) {
      for (const [id, o] of this.ops) {
        if (this.ops.size <= 200) break;
        if (o.state === 'done' || o.state === 'error') this.ops.delete(id);
      }
    }
    this.tick();
    return op;
  }

  /** Validates lines against the model as it will be after everything already queued. */
  protected dryRun(lines: string[]): void {
    const env = this.env(true);
    let m = cloneModel(this.model);
    for (const op of this.ops.values()) {
      if (op.state !== 'run' && op.state !== 'pend') continue;
      for (const l of op.lines.slice(op.next)) {
        const r = interpret(m, env, l);
        if (!('error' in r)) m = r.model;
      }
    }
    for (const l of lines) {
      const r = interpret(m, env, l);
      if ('error' in r) throw new G2Fail(r.error.code, `${l}: ${r.error.additional}`);
      m = r.model;
    }
  }

  protected finishOp(op: Op, err: GError | null): void {
    op.state = err ? 'error' : 'done';
    op.error = err
      ? { code: err.code, description: statusText(err.code), additional_description: err.additional }
      : null;
    this.pending = [];
    this.running = null;
    const job = op.jobId !== null ? this.jobs.get(op.jobId) : undefined;
    if (job && (job.state === 'running' || job.state === 'paused' || job.state === 'queued')) {
      job.state = err ? (err.code === 207 ? 'killed' : 'error') : 'done';
      job.finished = this.now();
    }
    if (!this.currentOp() && this.busy()) this.stat = this.ended ? 4 : 3;
    this.vel = 0;
    this.ended = false;
  }

  /**
   * Kill. On the operation in motion it is the firmware's queue flush + job kill (^D): motion
   * stops where it is, the planner forgets it and every operation queued behind it (a stop must
   * stop everything), the machine ends in stat 4 (End) as the 101.03 capture shows. On an
   * operation still pending it only removes that operation.
   */
  protected kill(op: Op, code = 207, additional = 'Job killed'): void {
    const wasRunning = op.state === 'run';
    if (wasRunning) {
      this.running = null;
      this.pending = [];
      // ^D "behaves like M30": program-end resets (G90, G94, G1, spindle off).
      this.model = {
        ...cloneModel(this.model),
        pos: { ...this.mpos },
        dist: 0,
        frmo: 1,
        momo: 1,
        spindle: 0,
      };
      this.hold = 0;
      this.finishOp(op, { code, additional });
      for (const o of this.ops.values()) {
        if (o.state === 'pend') this.finishOp(o, { code, additional: `flushed with operation ${op.id}` });
      }
      this.stat = 4;
      return;
    }
    this.finishOp(op, { code, additional });
  }

  /** Alarm, shutdown or panic: motion stops, every operation fails with `code`. */
  raise(stat: number, code: number, why: string): void {
    for (const op of this.ops.values())
      if (op.state === 'run' || op.state === 'pend') this.kill(op, code, why);
    this.running = null;
    this.pending = [];
    this.model = { ...cloneModel(this.model), pos: { ...this.mpos } };
    this.stat = stat;
    this.vel = 0;
  }

  protected findOp(id: string): Op {
    const op = this.ops.get(Number(id));
    if (!op) throw new G2Fail(100, `no operation ${id}`);
    return op;
  }

  protected opView(op: Op): Record<string, unknown> {
    const held = op.state === 'run' && (this.stat === 6 || this.stat === 11);
    const v: Record<string, unknown> = {
      id: op.id,
      optype: op.optype,
      opstate: held ? 'pause' : op.state,
      value: op.value,
      line: op.done,
    };
    if (op.error) v.error = op.error;
    if (op.replies.length > 0) v.r = op.replies;
    return v;
  }

  /** GET /operation: unfinished operations in the order they run, then the 20 latest finished. */
  protected opList(): Record<string, unknown>[] {
    const all = [...this.ops.values()];
    const active = all.filter((o) => o.state === 'run' || o.state === 'pend');
    const ended = all
      .filter((o) => !active.includes(o))
      .reverse()
      .slice(0, 20);
    return [...active, ...ended].map((o) => this.opView(o));
  }

  protected putOperation(op: Op, body: unknown): Response {
    const want = isRecord(body) ? body.opstate : undefined;
    const active = op.state === 'run' || op.state === 'pend';
    if (want === 'kill') {
      if (!active) throw new G2Fail(106, `operation ${op.id} is ${op.state}`);
      this.kill(op);
    } else if (want === 'pause') {
      if (op.state !== 'run' || this.stat === 6) throw new G2Fail(106, `operation ${op.id} is not moving`);
      this.stat = 6;
      this.hold = 4;
      this.vel = 0;
      this.setJobState(op, 'paused');
    } else if (want === 'run') {
      if (op.state !== 'run' || this.stat !== 6) throw new G2Fail(106, `operation ${op.id} is not held`);
      this.stat = this.running?.action.t === 'homeleg' ? 9 : 5;
      this.hold = 0;
      this.last = this.now();
      this.setJobState(op, 'running');
    } else throw new G2Fail(101, 'opstate must be "pause", "run" or "kill"');
    return jsonResponse(this.opView(op));
  }

  private setJobState(op: Op, state: SimJob['state']): void {
    const job = op.jobId !== null ? this.jobs.get(op.jobId) : undefined;
    if (job) job.state = state;
  }
}

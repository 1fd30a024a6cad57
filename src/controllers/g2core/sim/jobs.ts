import { jsonResponse } from '../../../fleet/sim';
import { G2Fail, isRecord } from './fail';
import { jobView, pruneEndedJobs, readJobUpload } from './job-wire';
import { G2coreMotion } from './motion';
import type { SimJob } from './state';

/**
 * The job queue of the simulated g2core (uploads wait there for a start and run one at a time as
 * `sendfile` operations) and the demo loop that feeds it. The fifth layer of the simulator.
 */

const MAX_JOB_BYTES = 4 * 1024 * 1024;

export const DEMO_JOB_NAME = 'demo-pocket.nc';
/** Between two demo runs: the simulated operator changes the stock. */
export const DEMO_PAUSE_MS = 15_000;

/**
 * The demo job: home (Z first, as the design's own example), then a 100 x 80 mm pocket cut in
 * three 1.5 mm steps with 4 mm zig-zag rows at 1500 mm/min: about 4.5 minutes and 150 lines, all
 * inside the 100.12 travel (X/Y 0..420, Z -95..0) with soft limits on.
 */
export function demoPocket(): string[] {
  const lines = ['G21 G90 G17 G94 G54', 'G28.2 Z0', 'G28.2 X0 Y0', 'M3 S12000', 'G4 P2', 'G0 Z-10'];
  for (const depth of [-21.5, -23, -24.5]) {
    lines.push('G0 X100 Y100', `G1 Z${depth} F300`, 'F1500');
    for (let i = 0, y = 100; y <= 180; i++, y += 4) {
      if (y > 100) lines.push(`G1 Y${y}`);
      lines.push(`G1 X${i % 2 === 0 ? 200 : 100}`);
    }
    lines.push('G0 Z-10');
  }
  lines.push('G0 Z-5', 'G0 X10 Y10', 'M5', 'M30');
  return lines;
}

export abstract class G2coreJobs extends G2coreMotion {
  protected async postJob(req: Request): Promise<Response> {
    const { name, text } = await readJobUpload(req, MAX_JOB_BYTES);
    const lines = text
      .split(/\r?\n/)
      .map((l) => l.trim())
      .filter((l) => l !== '' && !/^\(.*\)$/.test(l) && !l.startsWith(';'));
    if (lines.length === 0) throw new G2Fail(101, 'the job has no G-code lines');
    return jsonResponse(this.addJob(name, lines).id, 201);
  }

  /** Puts a job at the end of the queue (it waits there for a start). */
  private addJob(name: string, lines: string[]): SimJob {
    const job: SimJob = {
      id: ++this.jobSeq,
      name: name || `job-${this.jobSeq}.nc`,
      lines,
      state: 'queued',
      started: null,
      finished: null,
      operation: null,
    };
    this.jobs.set(job.id, job);
    this.queue.push(job.id);
    // Keep the finished history bounded (the demo loop queues a job every few minutes).
    pruneEndedJobs(this.jobs, 50);
    return job;
  }

  /** Starts a queued job as a `sendfile` operation. */
  protected startJob(job: SimJob): void {
    this.queue = this.queue.filter((id) => id !== job.id);
    // State first: addOp runs the first lines at once, and a job may end (in error) right there.
    job.state = 'running';
    job.started = this.now();
    const created = this.addOp('sendfile', String(job.id), job.lines, job.id);
    job.operation = created.id;
  }

  protected findJob(id: string): SimJob {
    const job = this.jobs.get(Number(id));
    if (!job) throw new G2Fail(100, `no job ${id}`);
    return job;
  }

  protected jobView(job: SimJob): Record<string, unknown> {
    const op = job.operation !== null ? this.ops.get(job.operation) : undefined;
    const pos = this.queue.indexOf(job.id);
    return jobView(job, op, pos < 0 ? null : pos);
  }

  protected jobList(): Record<string, unknown>[] {
    const active = [...this.jobs.values()].filter((j) => j.state === 'running' || j.state === 'paused');
    const queued = this.queue.map((id) => this.jobs.get(id)!);
    const finished = [...this.jobs.values()]
      .filter((j) => !active.includes(j) && !queued.includes(j))
      .sort((a, b) => (b.finished ?? 0) - (a.finished ?? 0))
      .slice(0, 20);
    return [...active, ...queued, ...finished].map((j) => this.jobView(j));
  }

  protected putJob(job: SimJob, body: unknown): Response {
    if (!isRecord(body)) throw new G2Fail(101, 'expected {"state":…} or {"position":…}');
    if (typeof body.position === 'number') {
      const i = this.queue.indexOf(job.id);
      if (i < 0) throw new G2Fail(106, `job ${job.id} is not queued`);
      const to = Math.max(0, Math.min(this.queue.length - 1, Math.round(body.position)));
      this.queue.splice(i, 1);
      this.queue.splice(to, 0, job.id);
      return jsonResponse(this.jobView(job));
    }
    const op = job.operation !== null ? this.ops.get(job.operation) : undefined;
    switch (body.state) {
      case 'run':
        if (job.state === 'queued') {
          const rejected = this.alarmed();
          if (rejected !== null) throw new G2Fail(rejected, 'clear the alarm first');
          // One job at a time; the next queued job never starts by itself (the operator checks the stock).
          if (this.currentOp()) throw new G2Fail(106, 'the machine is busy with another operation');
          this.startJob(job);
        } else if (op && job.state === 'paused') this.putOperation(op, { opstate: 'run' });
        else throw new G2Fail(106, `job ${job.id} is ${job.state}`);
        break;
      case 'pause':
        if (!op || job.state !== 'running') throw new G2Fail(106, `job ${job.id} is ${job.state}`);
        this.putOperation(op, { opstate: 'pause' });
        break;
      case 'kill':
        if (job.state === 'queued') {
          this.queue = this.queue.filter((id) => id !== job.id);
          job.state = 'killed';
          job.finished = this.now();
        } else if (op && (op.state === 'run' || op.state === 'pend')) this.kill(op);
        else throw new G2Fail(106, `job ${job.id} is ${job.state}`);
        break;
      default:
        throw new G2Fail(101, 'state must be "run", "pause" or "kill"');
    }
    return jsonResponse(this.jobView(job));
  }

  protected deleteJob(job: SimJob): Response {
    if (job.state === 'running' || job.state === 'paused')
      throw new G2Fail(106, `job ${job.id} is ${job.state}`);
    this.jobs.delete(job.id);
    this.queue = this.queue.filter((id) => id !== job.id);
    return new Response(null, { status: 204 });
  }

  // ------------------------------------------------------------------------------ demo loop
  // (what it does: see the `demo` field in state.ts)

  startDemo(): void {
    const id = this.demo?.jobId ?? null;
    const job = id !== null ? this.jobs.get(id) : undefined;
    if (job && ['queued', 'running', 'paused'].includes(job.state)) return;
    this.demo = { jobId: null, restartAt: this.now() };
    this.demoStep();
  }

  /** True while the demo loop is on (a demo job runs or the next one is due). */
  get demoRunning(): boolean {
    return this.demo !== null;
  }

  protected override demoStep(): void {
    const d = this.demo;
    if (!d) return;
    const job = d.jobId !== null ? this.jobs.get(d.jobId) : undefined;
    if (job && ['queued', 'running', 'paused'].includes(job.state)) return;
    if (job && job.state !== 'done') {
      this.demo = null;
      return;
    }
    if (d.restartAt === null) {
      d.restartAt = this.now() + DEMO_PAUSE_MS;
      return;
    }
    // Wait for a machine that could start: idle, no alarm, nothing else running.
    if (this.now() < d.restartAt || this.currentOp() || ![1, 3, 4].includes(this.stat)) return;
    const next = this.addJob(DEMO_JOB_NAME, demoPocket());
    d.jobId = next.id;
    d.restartAt = null;
    this.startJob(next);
  }
}

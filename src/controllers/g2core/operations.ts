import type { StoreApi } from 'zustand/vanilla';
import type { SessionContext } from '../../fleet/contract';
import { describeError, LinkError } from '../../fleet/errors';
import { isLinkFault } from '../../fleet/faults';
import type { RunToken } from '../../fleet/kernel';
import { g2StatusOf, type G2coreClient, type OpControl } from './client';
import {
  MOVING,
  activeTarget,
  describeStatus,
  finished,
  num,
  pruneOps,
  runningJob,
  type ConsoleEntry,
  type G2Detail,
  type TrackedOp,
} from './model';
import type { Operation } from './wire';

/**
 * The operations (`/operation`) this console tracks: the ones it started (jog, home, MDI), and
 * motion another console started that it found with `GET /operation`. Reads for the slow poll
 * (`read`, then `apply` while the run is current) and the command work on operations. Every
 * answer to a command is written only while the run that sent it is current.
 */

export interface OpsRead {
  ops: Array<{ id: string; op: Operation | null; gone: boolean }>;
  foreign: { list: Operation[] } | { unsupported: string } | null;
}

export interface OpsHost {
  readonly ctx: SessionContext;
  readonly client: G2coreClient;
  readonly detail: StoreApi<G2Detail>;
  /** The current run (to check before writing an answer). */
  run(): RunToken;
  /** Poll again right after any poll in flight; `jobs`: the job list too. */
  refresh(jobs?: boolean): void;
}

/** An operation's replies in words: the server's JSON, shortened; never thrown (too deep, too big). */
export function repliesText(r: ReadonlyArray<Record<string, unknown>> | undefined): string {
  if (!r || r.length === 0) return '';
  let text: string;
  try {
    text = r.map((x) => JSON.stringify(x)).join(' ');
  } catch {
    return '(a reply the console cannot show)';
  }
  return text.length > 500 ? `${text.slice(0, 500)}…` : text;
}

const moving = (t: TrackedOp) => t.op?.opstate.state === 'run' || t.op?.opstate.state === 'pause';

export class OpTracker {
  private consoleSeq = 0;

  constructor(private readonly host: OpsHost) {}

  private get state(): G2Detail {
    return this.host.detail.getState();
  }

  private set(patch: Partial<G2Detail> | ((d: G2Detail) => Partial<G2Detail>)): void {
    this.host.detail.setState(patch);
  }

  // ------------------------------------------------------------------------------ slow poll

  /** The states of the unfinished tracked operations (100 "unrecognized": gone). */
  async readTracked(signal: AbortSignal): Promise<OpsRead['ops']> {
    const out: OpsRead['ops'] = [];
    for (const t of Object.values(this.state.ops).filter((x) => !finished(x.op))) {
      try {
        out.push({ id: t.id, op: await this.host.client.operation(t.id, signal), gone: false });
      } catch (e) {
        // "Unrecognized" from the server itself: gone. A failed request says nothing (next poll).
        if (!isLinkFault(e) && g2StatusOf(e)?.code === 100) out.push({ id: t.id, op: null, gone: true });
      }
    }
    return out;
  }

  /**
   * The machine moves but nothing this console knows of does (another console's MDI or jog, or
   * a page reloaded mid-move): list the operations (`GET /operation`) to track the one that
   * moves, so that Feedhold, Cycle start and Kill act on it. Jobs need nothing: every console
   * sees them.
   */
  async readForeign(answers: OpsRead['ops'], signal: AbortSignal): Promise<OpsRead['foreign']> {
    const d = this.state;
    const st = num(d.sr.stat);
    if (!d.opsList || st === null || !MOVING.has(st) || runningJob(d.jobs)) return null;
    const fresh = new Map(answers.map((a) => [a.id, a.op]));
    if (Object.values(d.ops).some((t) => moving(fresh.has(t.id) ? { ...t, op: fresh.get(t.id) ?? null } : t)))
      return null;
    try {
      return { list: await this.host.client.operations(signal) };
    } catch (e) {
      // Only the server's own whole answer says it has no list; a failed request is the link's.
      if (e instanceof LinkError && !isLinkFault(e) && (e.status === 404 || e.status === 405))
        return { unsupported: describeError(e) };
      return null;
    }
  }

  apply({ ops, foreign }: OpsRead): void {
    for (const a of ops) this.update(a.id, a.op, a.gone);
    if (foreign && 'unsupported' in foreign) {
      this.set({ opsList: false });
      this.host.ctx.log.warn(
        'protocol',
        `GET /operation is not supported (${foreign.unsupported}): motion started elsewhere cannot be held from here`,
      );
    } else if (foreign) this.adopt(foreign.list);
  }

  private adopt(list: Operation[]): void {
    const now = this.host.ctx.now();
    const found: Record<string, TrackedOp> = {};
    list.forEach((op, i) => {
      const state = op.opstate.state;
      if (op.id === undefined || op.optype === 'sendfile') return;
      if (state !== 'run' && state !== 'pause' && state !== 'pend') return;
      const id = String(op.id);
      if (this.state.ops[id]) return;
      const lines = Array.isArray(op.value)
        ? op.value
        : typeof op.value === 'string'
          ? op.value.split(/\r?\n/)
          : [];
      // Keep the server's order (the running one first) ahead of anything tracked already.
      const label = `operation ${id} (started elsewhere)`;
      found[id] = { id, purpose: 'other', label, lines, op, startedAt: now - 1_000_000 + i };
    });
    const labels = Object.values(found).map((t) => t.label);
    if (labels.length === 0) return;
    this.set((s) => ({ ops: pruneOps({ ...s.ops, ...found }) }));
    this.host.ctx.log.info('console', `Tracking ${labels.join(', ')}`);
  }

  private update(id: string, op: Operation | null, gone = false): void {
    const t = this.state.ops[id];
    if (!t) return;
    const log = this.host.ctx.log;
    const was = t.op?.opstate.state;
    const next: TrackedOp = { ...t, op: gone ? { opstate: { state: 'done', raw: 'gone' } } : op };
    this.set((s) => ({ ops: { ...s.ops, [id]: next } }));
    const now = next.op?.opstate.state;
    if (now !== was && (now === 'done' || now === 'error')) {
      const code = next.op?.error?.code;
      const err = next.op?.error ? describeStatus(next.op.error) : null;
      if (err) {
        log.add(code === 207 ? 'warning' : 'error', 'controller', `${t.label}: ${err}`);
        if (code !== 207) this.set({ lastError: err });
      }
      const replies = repliesText(next.op?.r);
      if (t.purpose === 'mdi')
        this.updateConsole(id, now === 'done' ? 'done' : 'error', err ?? (replies || null));
      if (t.purpose === 'mdi' && replies) log.info('console', `< ${replies}`);
    } else if (t.purpose === 'mdi' && now === 'run') this.updateConsole(id, 'running', null);
  }

  private updateConsole(opId: string, state: ConsoleEntry['state'], message: string | null): void {
    this.set((s) => ({
      console: s.console.map((c) => (c.opId === opId ? { ...c, state, message: message ?? c.message } : c)),
    }));
  }

  // ------------------------------------------------------------------------------ command work

  async start(
    purpose: TrackedOp['purpose'],
    label: string,
    lines: string[],
    commandId: string,
  ): Promise<string> {
    const run = this.host.run();
    const id = await this.host.client.runOperation(lines, commandId);
    if (run.alive()) {
      const t: TrackedOp = { id, purpose, label, lines, op: null, startedAt: this.host.ctx.now() };
      this.set((s) => ({ ops: pruneOps({ ...s.ops, [id]: t }) }));
    }
    this.host.refresh();
    return id;
  }

  /** Feedhold, cycle start or kill of the running job, else of the operation in motion. */
  async control(what: OpControl, commandId: string): Promise<string> {
    const run = this.host.run();
    const target = activeTarget(this.state);
    if (!target) throw new Error('Nothing started from this console is running');
    if (target.kind === 'job') {
      await this.host.client.controlJob(target.id, { state: what }, commandId);
    } else {
      const op = await this.host.client.controlOperation(target.id, what, commandId);
      if (run.alive()) {
        this.update(target.id, op);
        // A kill flushes the queue: every operation behind it is gone too.
        if (what === 'kill')
          for (const t of Object.values(this.state.ops)) if (!finished(t.op)) void this.refreshOne(t.id, run);
      }
    }
    this.host.refresh(true);
    const words = { pause: 'held (feedhold)', run: 'resumed (cycle start)', kill: 'killed' }[what];
    return `${target.label} ${words}`;
  }

  /** The big STOP on a jog or homing. */
  async kill(op: TrackedOp, commandId: string): Promise<string> {
    await this.host.client.controlOperation(op.id, 'kill', commandId);
    this.host.refresh();
    return `${op.label} stopped`;
  }

  private async refreshOne(id: string, run: RunToken): Promise<void> {
    try {
      const op = await this.host.client.operation(id, run.signal);
      if (run.alive()) this.update(id, op);
    } catch {
      /* the next poll tries again */
    }
  }

  async clearAlarm(commandId: string): Promise<void> {
    const run = this.host.run();
    await this.host.client.clearAlarm(commandId);
    if (run.alive()) this.set({ lastError: null });
    this.host.refresh();
  }

  /** MDI: the lines run as one operation; the console shows its state and the status text. */
  async sendMdi(text: string, commandId: string): Promise<string> {
    const lines = text
      .split(/\r?\n/)
      .map((l) => l.trim())
      .filter((l) => l !== '');
    if (lines.length === 0) throw new Error('Nothing to send');
    const run = this.host.run();
    const log = this.host.ctx.log;
    const seq = ++this.consoleSeq;
    const entry: ConsoleEntry = {
      seq,
      at: this.host.ctx.now(),
      lines,
      opId: null,
      state: 'sent',
      message: null,
    };
    this.set((s) => ({ console: [...s.console.slice(-99), entry] }));
    const patch = (p: Partial<ConsoleEntry>) => {
      if (run.alive())
        this.set((s) => ({ console: s.console.map((c) => (c.seq === seq ? { ...c, ...p } : c)) }));
    };
    try {
      const id = await this.start(
        'mdi',
        `MDI ${lines[0]}${lines.length > 1 ? ` (+${lines.length - 1})` : ''}`,
        lines,
        commandId,
      );
      patch({ opId: id });
      log.info('console', `> ${lines.join(' | ')} → operation ${id}`);
      return `operation ${id}`;
    } catch (e) {
      const g = g2StatusOf(e);
      const message = g
        ? `${g.text}${g.additional ? ` — ${g.additional}` : ''} (status ${g.code})`
        : describeError(e);
      patch({ state: 'refused', message });
      log.warn('console', `> ${lines.join(' | ')} refused: ${message}`);
      throw e;
    }
  }
}

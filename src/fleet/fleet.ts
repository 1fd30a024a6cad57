import { createStore, type StoreApi } from 'zustand/vanilla';
import { MachineQueries } from './kernel/query';
import { createSharedStore } from './kernel/share';
import { currentPrincipal } from './auth';
import { CommandRunner, type Principal } from './commands';
import type { MachineSession, SessionContext } from './contract';
import { documentVisibility, type Visibility } from './link';
import { MachineLog } from './log';
import { emptySnapshot, type MachineInfo, type MachineSnapshot } from './types';

/** One machine at run time: its snapshot store, log, command runner and session. */
export interface MachineRuntime {
  info: MachineInfo;
  snapshot: StoreApi<MachineSnapshot>;
  log: MachineLog;
  commands: CommandRunner;
  /** The context its session gets (kept: the session is made when the family's code has loaded). */
  readonly ctx: SessionContext;
  /** Null until the family's code has loaded (or when it could not be made: `error`). */
  session: MachineSession | null;
  /** Set when the family module failed to create a session (shown in the tile, not thrown). */
  error: string | null;
}

export interface RuntimeOptions {
  visibility?: Visibility;
  now?: () => number;
  principal?: () => Principal;
  /** Whether the machine's details are shown (default: always). */
  detail?: () => boolean;
}

export type SessionFactory = (ctx: SessionContext) => MachineSession;

/** Builds the context a session gets. Used by the app and by tests. */
export function createContext(info: MachineInfo, opts: RuntimeOptions = {}): SessionContext {
  const now = opts.now ?? Date.now;
  const snapshot = createSharedStore<MachineSnapshot>(() => emptySnapshot(info.id));
  const log = new MachineLog(info.id, now);
  const queries = new MachineQueries(info.id);
  const commands = new CommandRunner(
    info.id,
    () => snapshot.getState(),
    log,
    opts.principal ?? currentPrincipal,
    now,
    (cmd) => {
      for (const key of cmd.invalidates ?? []) void queries.invalidate(key);
    },
  );
  return {
    machine: info,
    snapshot,
    log,
    commands,
    queries,
    visibility: opts.visibility ?? documentVisibility,
    detail: opts.detail ?? (() => true),
    now,
  };
}

/** How many open pages show each machine's details (`showDetail`). */
const detailShown = new Map<string, number>();

/** Whether a page shows this machine's details now. */
export const detailShownOf = (id: string) => (): boolean => (detailShown.get(id) ?? 0) > 0;

/** A machine page shows the machine's details from now on. Returns: it no longer does. */
export function showDetail(id: string): () => void {
  detailShown.set(id, (detailShown.get(id) ?? 0) + 1);
  let done = false;
  return () => {
    if (done) return;
    done = true;
    const n = (detailShown.get(id) ?? 1) - 1;
    if (n > 0) detailShown.set(id, n);
    else detailShown.delete(id);
  };
}

/**
 * A machine whose family's code is still loading: its tile shows "Connecting…" and its session
 * comes with `attachSession`.
 */
export function pendingRuntime(info: MachineInfo, opts: RuntimeOptions = {}): MachineRuntime {
  const ctx = createContext(info, opts);
  return {
    info,
    snapshot: ctx.snapshot,
    log: ctx.log,
    commands: ctx.commands,
    ctx,
    session: null,
    error: null,
  };
}

/**
 * Gives a runtime its session (`createSession` null: the family has no module, or `failure`: its
 * code could not be loaded). A failure is shown on the machine, never thrown.
 */
export function attachSession(
  rt: MachineRuntime,
  createSession: SessionFactory | null,
  failure?: string,
): void {
  let error: string | null = null;
  if (!createSession) {
    error = failure ?? `No controller module for kind "${rt.info.kind}"`;
  } else {
    try {
      rt.session = createSession(rt.ctx);
    } catch (e) {
      error = e instanceof Error ? e.message : String(e);
    }
  }
  rt.error = error;
  if (error) {
    rt.ctx.snapshot.setState({
      link: 'protocol-error',
      problem: { kind: 'internal', message: error },
      activityLabel: error,
    });
    rt.ctx.log.error('console', error);
  }
}

/** A runtime with its session made now (tests, and boot once a family has loaded). */
export function createRuntime(
  info: MachineInfo,
  createSession: SessionFactory | null,
  opts: RuntimeOptions = {},
): MachineRuntime {
  const rt = pendingRuntime(info, opts);
  attachSession(rt, createSession);
  return rt;
}

/** The fleet: the list of machines (reactive) and their runtimes (by id). */
export interface FleetState {
  status: 'loading' | 'ready' | 'error';
  error: string | null;
  machines: MachineInfo[];
}

export const fleetStore = createStore<FleetState>(() => ({ status: 'loading', error: null, machines: [] }));

const runtimes = new Map<string, MachineRuntime>();

export function registerRuntime(rt: MachineRuntime): void {
  runtimes.set(rt.info.id, rt);
}

export function getRuntime(id: string): MachineRuntime | undefined {
  return runtimes.get(id);
}

export function allRuntimes(): MachineRuntime[] {
  return [...runtimes.values()];
}

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
  session: MachineSession | null;
  /** Set when the family module failed to create a session (shown in the tile, not thrown). */
  error: string | null;
}

export interface RuntimeOptions {
  visibility?: Visibility;
  now?: () => number;
  principal?: () => Principal;
}

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
    now,
  };
}

export function createRuntime(
  info: MachineInfo,
  createSession: ((ctx: SessionContext) => MachineSession) | null,
  opts: RuntimeOptions = {},
): MachineRuntime {
  const ctx = createContext(info, opts);
  let session: MachineSession | null = null;
  let error: string | null = null;
  if (!createSession) {
    error = `No controller module for kind "${info.kind}"`;
  } else {
    try {
      session = createSession(ctx);
    } catch (e) {
      error = e instanceof Error ? e.message : String(e);
    }
  }
  if (error) {
    ctx.snapshot.setState({
      link: 'protocol-error',
      problem: { kind: 'internal', message: error },
      activityLabel: error,
    });
    ctx.log.error('console', error);
  }
  return { info, snapshot: ctx.snapshot, log: ctx.log, commands: ctx.commands, session, error };
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

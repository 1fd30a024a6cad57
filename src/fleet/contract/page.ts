import type { ComponentType } from 'react';
import type { StoreApi } from 'zustand/vanilla';
import type { CommandDecl, CommandRunner } from '../commands';
import type { MachineQueries } from '../kernel/query';
import type { Visibility } from '../link';
import type { MachineLog } from '../log';
import type { MachineInfo, MachineSnapshot, Role } from '../types';

/** A family's session and tabs as the page runs them. */

/** Everything a session gets from the console. */
export interface SessionContext {
  machine: MachineInfo;
  snapshot: StoreApi<MachineSnapshot>;
  log: MachineLog;
  commands: CommandRunner;
  /** On-demand reads of this machine (files, settings, stats): src/fleet/kernel/query.ts. */
  queries: MachineQueries;
  visibility: Visibility;
  /**
   * Whether a page shows this machine's details now (its machine page). Reads that only feed
   * details (positions at 4 Hz) may run at the tile's pace otherwise (issue 16: a fleet page of
   * 100 machines). True where nothing says otherwise (tests, the fault matrix).
   */
  detail: () => boolean;
  now: () => number;
}

export interface MachineSession {
  readonly machine: MachineInfo;
  readonly ctx: SessionContext;
  start(): void;
  /** Stop timers and sockets; say goodbye to the controller where the protocol wants it. */
  stop(): void;
  /** The declared commands, by id. */
  readonly commands: Readonly<Record<string, CommandDecl<never>>>;
  /** Acknowledge an alarm (clears the blocking banner; the controller may have its own ack). */
  acknowledgeAlarm?(alarmId: string): void;
  /** Log in when the machine says "needs login" (TouchCut user, Duet password). */
  login?(credentials: Record<string, string>): Promise<void>;
}

export interface TabProps<S extends MachineSession> {
  session: S;
}

export interface TabDecl<S extends MachineSession> {
  id: string;
  label: string;
  Component: ComponentType<TabProps<S>>;
  /** Least role that sees this tab at all (default viewer). */
  role?: Role;
}

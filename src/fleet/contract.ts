import type { ComponentType, ReactNode } from 'react';
import type { AccessPolicy, BodyNeeded } from './access';
import type { SimulatorFactory } from './sim';
import type { MachineKind } from './types';
import type { GatewayHints } from './contract/gateway';
import type { MachineSession, SessionContext, TabDecl, TabProps } from './contract/page';

/**
 * The controller contract: what a family module provides. A family is one folder under
 * `src/controllers/<kind>/`, listed in `src/controllers/index.ts` (browser) and `families.ts`
 * (Node-safe: no React views for the gateway). Parts in contract/: gateway.ts, held-session.ts,
 * streams.ts, watch.ts, page.ts (sessions, tabs), link-tracker.ts; re-exported here.
 */

export type { GatewayHints, SharingHints } from './contract/gateway';
export type {
  GatewaySecrets,
  HeldCredentials,
  HeldIntercept,
  HeldOpen,
  HeldSend,
  HeldSessionHooks,
  UpstreamAnswer,
  UpstreamRequest,
} from './contract/held-session';
export { LinkTracker, linkWords } from './contract/link-tracker';
export type { MachineSession, SessionContext, TabDecl, TabProps } from './contract/page';
export type {
  FanoutStreamDecl,
  FrameClass,
  JsonRecord,
  JsonValue,
  ModelStreamDecl,
  SharedStreamDecl,
} from './contract/streams';
export {
  watchAlarmsOf,
  watchStateOf,
  type TemperatureDecl,
  type TemperatureReading,
  type WatchAlarm,
  type WatchDecl,
  type WatchJobRecord,
  type WatchNews,
  type WatchSummary,
} from './contract/watch';

/**
 * Node-safe declaration of a family (`<kind>/declaration.ts`): used by the gateway, `npm run sim`
 * and the browser alike. No simulator: the browser never loads one (simulated machines are
 * answered by the gateway), so the production bundle carries none.
 */
export interface FamilyDeclaration {
  kind: MachineKind;
  /** "xTool D-series" */
  label: string;
  /** Which requests need which role, which are commands (audited). */
  access: AccessPolicy;
  /** Requests whose body the gateway must read to classify them. */
  accessNeedsBody?: BodyNeeded;
  /** The most of such a body the gateway reads (bytes), when more than its default (g2core's job upload). */
  accessBodyLimit?: (method: string, path: string) => number | undefined;
  gateway?: GatewayHints;
  /**
   * The family's job commands by what they do (ids of its declared commands): the job control row,
   * the kiosk and the production history (which command started, paused or stopped a job) read
   * them from here. A family whose API commands nothing (TouchCut) declares none.
   */
  jobs?: JobCommandIds;
}

/** A family's job commands by what they do (`X-Shopdeck-Command` ids, `<kind>.<command>`). */
export interface JobCommandIds {
  /** Starts a job from a file (the history attributes the job to who sent it). */
  start?: string;
  pause: string;
  resume: string;
  /** The job's stop (cancel, kill). */
  stop: string;
  /** The machine's emergency stop, where the console may send one (also ends the job). */
  estop?: string;
}

/** A control of the job control row (src/app/kiosk/JobControls.tsx). */
export type JobControlKind = 'pause' | 'resume' | 'stop' | 'estop';

/**
 * A family's manifest (`<kind>/manifest.ts`): what the console knows of the family before its code
 * loads. Plain data, small and Node-safe (no React, no views: loaders only): the shell carries
 * every family's, and the family's declaration takes its kind, label and job commands from it.
 * `src/controllers/index.ts` lists each family once, by its manifest and its page module.
 */
export interface FamilyManifest {
  kind: MachineKind;
  /** "xTool D-series" */
  label: string;
  /** The family's job commands by what they do (see `FamilyDeclaration.jobs`). */
  jobs?: JobCommandIds;
  /** The job control row's words of this family (with `jobs`; without it, state and progress only). */
  kiosk?: KioskManifest;
  /** Family-level pages outside any machine, routed at `/<kind>/<path>` (their code loads when shown). */
  pages?: FamilyPageManifest[];
  /** What the production history keeps of this family beyond jobs and states. */
  history?: {
    /** The name of the daily statistics the console server imports from its controllers. */
    statisticsDays?: string;
  };
}

export interface KioskManifest {
  /** The firmware's own term for each control (the subtitle under the shared word). */
  terms: Partial<Record<JobControlKind, string>>;
  /** What dismissing the job stop's question keeps ("Keep printing"). */
  keep: string;
  /**
   * A view of the family's own shown below the controls in the kiosk: by convention its
   * `views/KioskExtra.tsx` (the bundle report looks for it there), a chunk of its own.
   */
  extra?: () => Promise<{ KioskExtra: (props: TabProps<never>) => ReactNode }>;
}

export interface FamilyPageManifest {
  path: string;
  label: string;
  load: () => Promise<() => ReactNode>;
}

/** A family as Node sees it (`<kind>/family.ts`): its declaration and its simulator. */
export interface FamilyDescriptor extends FamilyDeclaration {
  createSimulator: SimulatorFactory;
}

/**
 * A family's page code (`<kind>/module.tsx`). Its name and kind only of the declaration: the
 * access rules and the gateway's hints are the console server's (they stay out of the page's
 * bundle, issue 16).
 */
export interface ControllerModule<S extends MachineSession = MachineSession> extends Pick<
  FamilyDeclaration,
  'kind' | 'label'
> {
  createSession(ctx: SessionContext): S;
  /** Tabs of the machine page; the first is the overview. */
  tabs: TabDecl<S>[];
  /** Optional extra on the fleet tile (a screenshot thumbnail). */
  TileExtra?: ComponentType<TabProps<S>>;
  /** Optional login form when the link says needs-login. */
  LoginForm?: ComponentType<TabProps<S>>;
}

/** Erases the session type so modules of all families fit one registry. */
export function defineController<S extends MachineSession>(m: ControllerModule<S>): ControllerModule {
  return m as unknown as ControllerModule;
}

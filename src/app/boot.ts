import { z } from 'zod/mini';
import { familyLabel, loadController, MACHINE_KINDS, registerController } from '../controllers';
import { authStore } from '../fleet/auth';
import {
  allRuntimes,
  attachSession,
  detailShownOf,
  fleetStore,
  getRuntime,
  pendingRuntime,
  registerRuntime,
  type MachineRuntime,
} from '../fleet/fleet';
import { backoffDelay } from '../fleet/link';
import { pageScheduler } from '../fleet/kernel/scheduler';
import type { MachineInfo, MachineKind, ServerJobRecord } from '../fleet/types';
import { CONSOLE_HEADERS } from '../fleet/origin';
import { startReadSocket } from '../fleet/read-socket';
import { setJobRecords } from '../fleet/job-records';
import { fetchSession, trackActivity } from './auth/api';
import { afterFirstScreen, firstScreenShown, onFirstScreen, readWatch } from './first-screen';
import { untilReachable } from './pwa/reach';
import { matchRoute, onLocationChange } from './router';

const MachinesAnswer = z.object({
  machines: z.array(
    z.object({
      id: z.string(),
      name: z.string(),
      kind: z.enum(MACHINE_KINDS),
      simulated: z.boolean(),
      group: z.optional(z.string()),
      watch: z.optional(z.unknown()),
    }),
  ),
});

export async function loadSession(): Promise<void> {
  try {
    // No answer at all (offline, server down): "Console unreachable — retrying" until it answers.
    await untilReachable(fetchSession);
  } catch {
    // A gateway without access control: behave as open mode, and say so in the banner.
    authStore.setState({ mode: 'open', user: null });
  }
  trackActivity();
}

/**
 * Loads the fleet, creates and starts one session per machine. Simulated machines are answered by
 * the gateway's simulators like hardware (one simulated world for every tab): nothing is
 * simulated in the page.
 */
export async function boot(): Promise<void> {
  // The machine list is asked for beside the session, not after it (index.html preloads it, so
  // the browser has it on its way before this code has loaded): the first screen waits for one
  // round trip, not three in a row (issue 34). Its failure is read below, where it is awaited.
  const machinesAnswer = untilReachable(() => fetch('/api/machines', { credentials: 'same-origin' }));
  machinesAnswer.catch(() => undefined);
  await loadSession();
  // The machines' polls go over one socket to the console server (read-socket.ts): HTTP until it is open.
  const reads = startReadSocket();
  let machines: MachineInfo[];
  const unreadable = new Set<string>();
  try {
    const r = await machinesAnswer;
    if (r.status === 401) {
      fleetStore.setState({ status: 'ready', machines: [], error: null });
      return;
    }
    if (!r.ok) throw new Error(`the gateway answered HTTP ${r.status}`);
    const parsed = MachinesAnswer.safeParse(await r.json());
    if (!parsed.success)
      throw new Error(`the machine list is malformed: ${parsed.error.issues[0]?.message ?? ''}`);
    // The server's reading of each machine is read on its own: a bad one is left out (and said in
    // that machine's log below), not the fleet.
    machines = parsed.data.machines.map(({ watch, ...m }) => {
      const w = readWatch(watch);
      if (watch !== undefined && !w) unreadable.add(m.id);
      return w ? { ...m, watch: w } : m;
    });
  } catch (e) {
    fleetStore.setState({
      status: 'error',
      error: `Cannot load the fleet: ${e instanceof Error ? e.message : String(e)}`,
    });
    return;
  }
  // The server's job records: every view's job facts (fleet/job-facts.ts), refreshed while open.
  setJobRecords(new Map(machines.map((m) => [m.id, m.watch?.record ?? null])), Date.now());
  refreshJobRecords();
  const created: MachineRuntime[] = [];
  for (const m of machines) {
    if (getRuntime(m.id)) continue;
    // Its detail reads run at full pace only while its machine page shows.
    const rt = pendingRuntime(m, { detail: detailShownOf(m.id) });
    registerRuntime(rt);
    created.push(rt);
    if (unreadable.has(m.id))
      rt.log.warn(
        'console',
        'the console server’s last reading of this machine was malformed: it waits for its own',
      );
  }
  fleetStore.setState({ status: 'ready', machines, error: null });
  // Each family's code loads on its own; its machines start when it is there. On a machine's
  // page that machine's family comes first and the others when the browser is idle after it. A
  // kiosk tablet (`/m/<id>?kiosk`) runs its own machine's session only: another machine's
  // critical alarm reaches it from the alarm centre, which the gateway's watch keeps for every
  // machine, so the tablet does not poll the whole fleet (the others start if it leaves the kiosk).
  const started = new Set<MachineRuntime>();
  const start = (rts: readonly MachineRuntime[]): void => {
    const fresh = rts.filter((rt) => !started.has(rt));
    for (const rt of fresh) started.add(rt);
    for (const kind of new Set(fresh.map((rt) => rt.info.kind)))
      startFamily(
        kind,
        fresh.filter((rt) => rt.info.kind === kind),
      );
  };
  const inView = created.find((rt) => rt.info.id === machineInView());
  // The first screen (first-screen.ts): on a machine's page, once that machine has answered (or
  // could not: any state but "connecting"), or a few seconds at the latest (a kiosk tablet's as
  // soon as it shows the server's reading of its machine: KioskPage); on the fleet page,
  // once its tiles show (FleetPage); elsewhere at once. What it does not need waits for it: the
  // other families' code, the alarm layer, the service worker.
  if (inView) {
    const stopWatching = inView.snapshot.subscribe((s) => {
      if (s.link !== 'connecting') shown();
    });
    const cancelShown = pageScheduler.after(OTHERS_AFTER_MS, shown);
    function shown(): void {
      stopWatching();
      cancelShown();
      firstScreenShown();
    }
  } else if (!fleetInView()) firstScreenShown();
  if (inView && kioskInView()) {
    // A kiosk tablet with the server's reading of its machine paints from it first (KioskPage);
    // the machine's family code loads at once after that (not at idle: its controls come with it),
    // or after a few seconds at the latest. Without a reading, the code loads at once.
    if (inView.info.watch) {
      const go = (): void => {
        cancelFallback();
        stopWaiting();
        start([inView]);
      };
      const cancelFallback = pageScheduler.after(OTHERS_AFTER_MS, go);
      const stopWaiting = onFirstScreen(go);
    } else start([inView]);
    const stop = onLocationChange(() => {
      if (kioskInView()) return;
      stop();
      start(created);
    });
  } else if (inView) {
    // The machine in view's family first, the others when the browser is idle after it answered.
    start(created.filter((rt) => rt.info.kind === inView.info.kind));
    afterFirstScreen(() => start(created), 2 * OTHERS_AFTER_MS);
  } else if (fleetInView()) {
    // The fleet page paints first, from the server's readings in the machines list; the families'
    // code loads when the browser is idle after that (or after a few seconds at the latest: a
    // page that never shows its tiles still starts its machines).
    afterFirstScreen(() => start(created), OTHERS_AFTER_MS);
  } else start(created);
  window.addEventListener('pagehide', () => {
    for (const rt of allRuntimes()) rt.session?.stop();
    reads?.close();
  });
}

/** How often an open page asks the server again for its job records (its watch reads each few s). */
const JOB_RECORDS_EVERY_MS = 5000;

/**
 * Asks `GET /api/machines` again every few seconds for the server's job records (name, start,
 * progress): the one source of every view's job facts. A hidden page does not ask; a failed or
 * malformed answer changes nothing (the records stay as last received, the next try comes).
 */
function refreshJobRecords(): void {
  const stop = pageScheduler.every(JOB_RECORDS_EVERY_MS, () => {
    if (document.hidden) return;
    void fetch('/api/machines', { credentials: 'same-origin', headers: CONSOLE_HEADERS })
      .then(async (r) => {
        if (!r.ok) return;
        const parsed = MachinesAnswer.safeParse(await r.json());
        if (!parsed.success) return;
        const next = new Map<string, ServerJobRecord | null>();
        for (const m of parsed.data.machines) {
          const w = readWatch(m.watch);
          // No reading (nothing watched, a bad one): the record stays as it was.
          if (w) next.set(m.id, w.record ?? null);
        }
        setJobRecords(next, Date.now());
      })
      .catch(() => undefined);
  });
  window.addEventListener('pagehide', stop);
}

/** The machine whose page is open (`/m/<id>…`), if one is (the router's reading of the address). */
function machineInView(): string | null {
  const r = matchRoute(location.pathname, location.search);
  return r.name === 'machine' ? r.id : null;
}

/** A kiosk tablet's page (`/m/<id>?kiosk`) is open. */
function kioskInView(): boolean {
  const r = matchRoute(location.pathname, location.search);
  return r.name === 'machine' && r.kiosk === true;
}

/** The fleet page (`/`) is open. */
function fleetInView(): boolean {
  return matchRoute(location.pathname, location.search).name === 'fleet';
}

/** On a machine's page, the other families start at the latest this long after boot. */
const OTHERS_AFTER_MS = 3000;

/** Tries to load a family's code this many times (backing off) before saying so on its machines. */
const FAMILY_LOAD_TRIES = 4;

/**
 * Loads a family's code, then makes and starts its machines' sessions. A chunk that cannot be
 * loaded (the console server restarting, a flaky network) is tried again; after that the
 * machines say why they show nothing.
 */
export function startFamily(kind: MachineKind, rts: MachineRuntime[], attempt = 0): void {
  loadController(kind).then(
    (mod) => {
      for (const rt of rts) attachSession(rt, (ctx) => mod.createSession(ctx));
      registerController(mod);
      for (const rt of rts) {
        try {
          rt.session?.start();
        } catch (e) {
          rt.log.error('console', `session failed to start: ${e instanceof Error ? e.message : String(e)}`);
        }
      }
    },
    (e: unknown) => {
      if (attempt + 1 < FAMILY_LOAD_TRIES) {
        pageScheduler.after(backoffDelay(attempt), () => startFamily(kind, rts, attempt + 1));
        return;
      }
      const why = e instanceof Error ? e.message : String(e);
      for (const rt of rts)
        attachSession(
          rt,
          null,
          `The console could not load its ${familyLabel(kind)} code (${why}). Reload the page.`,
        );
    },
  );
}

import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it, vi } from 'vitest';
import type { Principal } from '../../fleet/commands';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import {
  FaultySimulator,
  type SimControl,
  type SimSocket,
  type SimSocketHandler,
  type Simulator,
} from '../../fleet/sim';
import { filesKey, SETTINGS_KEY } from './queries';
import { POLL_IDLE_MS, SOCKET_QUIET_MS, XtoolSession, type XtoolSettings } from './session';
import { XtoolSimulator } from './sim/simulator';
import type { FileList } from './wire';

/**
 * The xTool session on the session kernel (issue 12): nothing written after stop, a poll right
 * after a command, the status socket's heartbeat policy, reads and their invalidation.
 */

const server = setupServer();
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());

/** Between the session and the simulated laser: counts requests and sockets, holds answers. */
class Probe implements Simulator {
  readonly kind = 'xtool' as const;
  readonly requests: string[] = [];
  sockets = 0;
  private holds: Array<{ prefix: string; gate: Promise<void>; waiting: number }> = [];

  constructor(
    readonly inner: Simulator,
    private readonly allowSockets = true,
  ) {}

  count(prefix: string): number {
    return this.requests.filter((p) => p.startsWith(prefix)).length;
  }

  /** Holds every answer to a path starting with `prefix` until `release()`. */
  hold(prefix: string): { release: () => void; waiting: () => number } {
    let release!: () => void;
    const h = { prefix, gate: new Promise<void>((r) => (release = r)), waiting: 0 };
    this.holds.push(h);
    return {
      release: () => {
        this.holds = this.holds.filter((x) => x !== h);
        release();
      },
      waiting: () => h.waiting,
    };
  }

  async fetch(req: Request, path: string): Promise<Response> {
    this.requests.push(path);
    const h = this.holds.find((x) => path.startsWith(x.prefix));
    if (h) {
      h.waiting++;
      await h.gate;
    }
    return this.inner.fetch(req, path);
  }

  socket(path: string, sock: SimSocket): SimSocketHandler | null {
    if (!this.allowSockets) return null;
    const h = this.inner.socket?.(path, sock) ?? null;
    if (h) this.sockets++;
    return h;
  }

  controls(): SimControl[] {
    return this.inner.controls?.() ?? [];
  }

  dispose(): void {
    this.inner.dispose();
  }
}

let seq = 0;
let session: XtoolSession | null = null;
let sim: XtoolSimulator | null = null;

beforeEach(() => {
  vi.useFakeTimers({ toFake: ['setTimeout', 'clearTimeout', 'setInterval', 'clearInterval', 'Date'] });
});
afterEach(() => {
  session?.stop();
  sim?.dispose();
  session = null;
  sim = null;
  server.resetHandlers();
  vi.useRealTimers();
});

function setup(opts: { sockets?: boolean; faulty?: boolean } = {}) {
  const id = `kx-${++seq}`;
  sim = new XtoolSimulator({ id, name: 'Kernel laser' });
  const faulty = opts.faulty ? new FaultySimulator(sim) : null;
  const probe = new Probe(faulty ?? sim, opts.sockets ?? true);
  server.use(...simulatorHandlers(id, probe));
  const principal = (): Principal => ({ name: 'tester', role: 'supervisor' });
  const ctx = createContext(
    { id, name: 'Kernel laser', kind: 'xtool', simulated: true },
    { visibility: alwaysVisible, principal },
  );
  session = new XtoolSession(ctx);
  return { sim, probe, faulty, session, ctx };
}

async function advance(ms: number): Promise<void> {
  for (let t = 0; t < ms; t += 50) await vi.advanceTimersByTimeAsync(50);
}

async function until(cond: () => boolean, maxMs = 15_000): Promise<void> {
  for (let t = 0; t < maxMs && !cond(); t += 50) await vi.advanceTimersByTimeAsync(50);
  expect(cond()).toBe(true);
}

const STATUS = '/system?action=get_working_sta';

describe('after a command (issue 12, defect 4)', () => {
  it('a command sent while a status poll is in flight is followed by the next poll at once', async () => {
    // No socket: the polls are all the console learns from (a frame would poll by itself).
    const { sim, probe, session, ctx } = setup({ sockets: false });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    const gate = probe.hold(STATUS);
    await until(() => gate.waiting() === 1, POLL_IDLE_MS + 500); // an idle poll is on its way
    const reads = probe.count(STATUS);
    const sent = ctx.commands.run(session.runFile, { path: '/jobs/coaster.gcode' });
    gate.release(); // the poll read "idle": the laser had not started yet
    await sent;
    expect(sim.job?.startedBy).toBe('api');
    await advance(300); // not an idle interval (10 s) later
    expect(probe.count(STATUS)).toBe(reads + 1);
    expect(session.detail.getState().machine).toMatchObject({ state: 'running', startedBy: 'api' });
    // The poll that began before the remote start did not erase its name.
    expect(ctx.snapshot.getState().job?.name).toBe('coaster.gcode');
  });
});

describe('nothing is written after stop', () => {
  it('a status poll answered after stop changes no store, and no request follows', async () => {
    const { sim, probe, session, ctx } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online' && session.detail.getState().socketOpen);
    const gate = probe.hold(STATUS);
    await until(() => gate.waiting() === 1, POLL_IDLE_MS + 500);
    session.stop();
    const detail = session.detail.getState();
    const snap = ctx.snapshot.getState();
    const log = ctx.log.store.getState().entries.length;
    const requests = probe.requests.length;
    sim.loadDemoJob(); // the held answer would now say "loaded", and a frame is sent
    gate.release();
    await advance(POLL_IDLE_MS * 3);
    expect(session.detail.getState()).toBe(detail);
    expect(ctx.snapshot.getState()).toBe(snap);
    expect(ctx.log.store.getState().entries).toHaveLength(log);
    expect(probe.requests).toHaveLength(requests);
  });

  it("a command's answer after stop changes no store", async () => {
    const { sim, probe, session, ctx } = setup();
    session.start();
    await until(() => session.detail.getState().socketOpen);
    sim.loadDemoJob();
    sim.pressButton();
    await until(() => session.detail.getState().machine.state === 'running');
    const gate = probe.hold('/cnc/data');
    const sent = ctx.commands.run(session.pause, undefined);
    await until(() => gate.waiting() === 1, 1000);
    session.stop();
    const detail = session.detail.getState();
    const snap = ctx.snapshot.getState();
    gate.release();
    await expect(sent).resolves.toBe('job paused'); // the laser paused; the console is gone
    await advance(POLL_IDLE_MS);
    expect(session.detail.getState()).toBe(detail);
    expect(ctx.snapshot.getState()).toBe(snap);
  });
});

describe('the status socket (heartbeat policy)', () => {
  it('a socket silent for the quiet time is reopened, and the new one delivers', async () => {
    const { sim, probe, session, ctx } = setup();
    session.start();
    await until(() => session.detail.getState().socketOpen);
    expect(probe.sockets).toBe(1);
    await advance(SOCKET_QUIET_MS - 10_000);
    expect(probe.sockets).toBe(1); // quiet, but not for long enough
    await until(() => probe.sockets === 2, 20_000);
    await until(() => session.detail.getState().socketOpen, 5000);
    expect(ctx.log.store.getState().entries.some((e) => /status socket: No data/.test(e.text))).toBe(true);
    sim.loadDemoJob();
    await until(() => session.detail.getState().lastFrame?.raw === 'ok:WORKING_ONLINE_READY', 1000);
    expect(session.detail.getState().source).toBe('socket');
    expect(ctx.snapshot.getState().link).toBe('online');
  });

  it('a socket that stayed open while the laser was unreachable is reopened when it is back', async () => {
    const { probe, faulty, session, ctx } = setup({ faulty: true });
    session.start();
    await until(() => session.detail.getState().socketOpen);
    // The laser is switched off: HTTP fails, and its socket neither speaks nor closes (no FIN).
    faulty?.setFaults({ drop: true });
    await until(() => ctx.snapshot.getState().link === 'offline', 60_000);
    expect(probe.sockets).toBe(1);
    faulty?.setFaults({ drop: false });
    await until(() => ctx.snapshot.getState().link === 'online', 60_000);
    await until(() => probe.sockets === 2, 5000);
    await until(() => session.detail.getState().socketOpen, 5000);
  });
});

describe('on-demand reads', () => {
  it('a settings command makes the settings stale: where they are shown, they are read again at once', async () => {
    const { session, ctx } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    // What the Safety tab does (useXtoolSettings): observe the settings read.
    const shown = ctx.queries.watch<XtoolSettings>(SETTINGS_KEY, session.reads.settings, {
      staleTimeMs: 60_000,
    });
    const unsubscribe = shown.subscribe(() => undefined);
    await until(() => shown.view.data?.periphery?.tiltStopFlag === true, 1000);
    await ctx.commands.run(session.tiltStopOff, undefined);
    await until(() => shown.view.data?.periphery?.tiltStopFlag === false, 500);
    expect(session.detail.getState().periphery?.tiltStopFlag).toBe(false);
    unsubscribe();
  });

  it('a delete refetches the folder shown; an upload shows its verified listing without asking again', async () => {
    const { probe, session, ctx } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    const shown = ctx.queries.watch<FileList>(filesKey('/jobs'), session.reads.files('/jobs'), {
      staleTimeMs: 30_000,
    });
    const unsubscribe = shown.subscribe(() => undefined);
    await until(() => (shown.view.data?.name.length ?? 0) > 0, 1000);
    const file = new Blob(['G1 X1\n']);
    await ctx.commands.run(session.upload, {
      file,
      name: 'new.gcode',
      target: { kind: 'path', filename: '/jobs/new.gcode' },
    });
    const lists = probe.count('/list');
    expect(shown.view.data?.name.some((n) => n.endsWith('new.gcode'))).toBe(true);
    await ctx.commands.run(session.deleteFile, { path: '/jobs/new.gcode' });
    await until(() => !shown.view.data?.name.some((n) => n.endsWith('new.gcode')), 500);
    expect(probe.count('/list')).toBe(lists + 1);
    unsubscribe();
  });

  it('on stop, reads in flight are cancelled and the cache is dropped', async () => {
    const { probe, session, ctx } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    expect(ctx.queries.size).toBeGreaterThan(0);
    const gate = probe.hold('/list');
    const read = ctx.queries.fetch(filesKey('/'), session.reads.files('/'));
    read.catch(() => undefined);
    await until(() => gate.waiting() === 1, 1000);
    session.stop();
    gate.release();
    await expect(read).rejects.toBeTruthy();
    expect(ctx.queries.size).toBe(0);
    await expect(session.reads.files('/')(new AbortController().signal)).rejects.toThrow(/not connected/);
  });
});

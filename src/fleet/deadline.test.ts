import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import {
  CommandNotConfirmed,
  commandHistory,
  DEADLINE_GRACE_MS,
  DEFAULT_COMMAND_DEADLINE_MS,
  IN_DOUBT_AFTER_MS,
  type CommandDecl,
} from './commands';
import { LinkError } from './errors';
import { installFakeFetch, type FakeFetch } from './fake-fetch.test-util';
import { createContext } from './fleet';
import { HttpClient, uploadWithProgress } from './http';
import { alwaysVisible } from './link';

/**
 * Issue 15: a command not confirmed within its deadline is reported "not confirmed: it may or may
 * not have reached the machine" — never "failed", never retried — and the machine is read again.
 * The browser sends the deadline to the gateway with the command (`X-Shopdeck-Deadline`), uses the
 * same deadline for its own timeout, and sends nothing of a command once its deadline has passed.
 * Fake timers, and a fetch the test answers by hand.
 */

const NOT_CONFIRMED = /not confirmed: it may or may not have reached the machine — check the machine's state/;

let f: FakeFetch;
beforeEach(() => {
  vi.useFakeTimers();
  f = installFakeFetch();
});
afterEach(() => {
  vi.useRealTimers();
  vi.unstubAllGlobals();
});

function setup() {
  const ctx = createContext(
    { id: 'm1', name: 'Printer 1', kind: 'prunt', simulated: false },
    { visibility: alwaysVisible, principal: () => ({ name: 'ann', role: 'supervisor' }) },
  );
  ctx.snapshot.setState({ link: 'online', activity: 'running', updatedAt: Date.now() });
  const client = new HttpClient({ machineId: 'm1' });
  let performed = 0;
  const command = (extra: Partial<CommandDecl<void>> = {}): CommandDecl<void> => ({
    id: 'test.pause',
    label: 'Pause',
    hazard: 'job',
    role: 'operator',
    confirm: false,
    perform: async (_a, c) => {
      performed++;
      await client.raw({ method: 'POST', path: '/pause', commandId: c.commandId });
      return 'paused';
    },
    ...extra,
  });
  return { ctx, client, command, performed: () => performed };
}

/** A promise's state without waiting for it. */
function track<T>(p: Promise<T>): { settled: () => boolean; result: Promise<T> } {
  let settled = false;
  p.then(
    () => (settled = true),
    () => (settled = true),
  );
  return { settled: () => settled, result: p };
}

async function rejection(p: Promise<unknown>): Promise<unknown> {
  try {
    await p;
  } catch (e) {
    return e;
  }
  throw new Error('expected a rejection');
}

describe('command deadlines (browser)', () => {
  it('sends the deadline with the command; not confirmed at the deadline: "not confirmed", never "failed", never retried', async () => {
    const t = setup();
    const refreshed: string[] = [];
    t.ctx.commands.onUnconfirmed((cmd) => refreshed.push(cmd.id));
    const run = track(t.ctx.commands.run(t.command(), undefined));
    await vi.advanceTimersByTimeAsync(0);
    expect(f.calls).toHaveLength(1);
    expect(f.last().headers.get('X-Shopdeck-Command')).toBe('test.pause');
    expect(f.last().headers.get('X-Shopdeck-Deadline')).toBe(String(DEFAULT_COMMAND_DEADLINE_MS));
    // The gateway answers 504 at the deadline; here it says nothing at all: the browser's own
    // timeout is the same deadline (and a moment for the gateway's answer to arrive).
    await vi.advanceTimersByTimeAsync(DEFAULT_COMMAND_DEADLINE_MS + DEADLINE_GRACE_MS - 1);
    expect(run.settled()).toBe(false);
    await vi.advanceTimersByTimeAsync(1);
    expect(run.settled()).toBe(true);
    const e = await rejection(run.result);
    expect(e).toBeInstanceOf(CommandNotConfirmed);
    expect((e as Error).message).toMatch(NOT_CONFIRMED);
    expect((e as Error).message).not.toMatch(/failed/i);
    // Its request is given up: the gateway sees the browser leave and drops it if not yet sent.
    expect(f.last().signal.aborted).toBe(true);
    const st = t.ctx.commands.state.getState();
    expect(st.inFlight['test.pause']).toBeUndefined();
    expect(st.last['test.pause']).toMatchObject({ ok: false, notConfirmed: true });
    const log = t.ctx.log.store.getState().entries.at(-1);
    expect(log?.text).toMatch(/not confirmed/);
    expect(log?.text).not.toMatch(/failed/i);
    expect(commandHistory.getState().records[0]).toMatchObject({
      commandId: 'test.pause',
      ok: false,
      outcome: 'not-confirmed',
    });
    // Never retried, and the session is asked to read the machine again.
    await vi.advanceTimersByTimeAsync(60_000);
    expect(t.performed()).toBe(1);
    expect(f.calls).toHaveLength(1);
    expect(refreshed).toEqual(['test.pause']);
  });

  it('a declared deadline is sent; a later request of the same command gets what is left of it', async () => {
    const t = setup();
    const cmd = t.command({
      deadlineMs: 2000,
      perform: async (_a, c) => {
        await t.client.raw({ method: 'POST', path: '/one', commandId: c.commandId });
        await new Promise((r) => setTimeout(r, 1500));
        await t.client.raw({ method: 'POST', path: '/two', commandId: c.commandId });
        return 'done';
      },
    });
    const run = t.ctx.commands.run(cmd, undefined);
    await vi.advanceTimersByTimeAsync(0);
    expect(f.last().headers.get('X-Shopdeck-Deadline')).toBe('2000');
    f.last().answer(200, '{}');
    await vi.advanceTimersByTimeAsync(1500);
    expect(f.calls).toHaveLength(2);
    expect(f.last().headers.get('X-Shopdeck-Deadline')).toBe('500');
    f.last().answer(200, '{}');
    await expect(run).resolves.toBe('done');
  });

  it('nothing of a command is sent once its deadline has passed', async () => {
    const t = setup();
    const cmd = t.command({
      deadlineMs: 1000,
      perform: async (_a, c) => {
        await t.client.raw({ method: 'POST', path: '/one', commandId: c.commandId });
        await new Promise((r) => setTimeout(r, 1200));
        await t.client.raw({ method: 'POST', path: '/two', commandId: c.commandId });
        return 'done';
      },
    });
    const run = track(t.ctx.commands.run(cmd, undefined));
    await vi.advanceTimersByTimeAsync(0);
    f.last().answer(200, '{}');
    await vi.advanceTimersByTimeAsync(1200);
    expect(run.settled()).toBe(true);
    expect(await rejection(run.result)).toBeInstanceOf(CommandNotConfirmed);
    expect(f.calls.map((c) => c.url.replace(/^.*\/machines\/m1/, ''))).toEqual(['/one']);
  });

  it('the gateway’s 504 "not confirmed" is reported at once, in the same words', async () => {
    const t = setup();
    const run = track(t.ctx.commands.run(t.command(), undefined));
    await vi.advanceTimersByTimeAsync(0);
    f.last().answer(
      504,
      JSON.stringify({
        error:
          'Printer 1 did not confirm pause the job within 5 s: it may or may not have reached the machine',
        gateway: true,
        notConfirmed: true,
      }),
      { 'X-Shopdeck-Gateway': 'error' },
    );
    await vi.advanceTimersByTimeAsync(0);
    expect(run.settled()).toBe(true);
    const e = await rejection(run.result);
    expect(e).toBeInstanceOf(CommandNotConfirmed);
    expect((e as Error).message).toMatch(NOT_CONFIRMED);
    expect(t.ctx.log.store.getState().entries.at(-1)?.text).toMatch(
      /did not confirm pause the job within 5 s/,
    );
  });

  it('a command the gateway could not send at all is a failure that says it was not sent', async () => {
    const t = setup();
    const run = track(t.ctx.commands.run(t.command(), undefined));
    await vi.advanceTimersByTimeAsync(0);
    f.last().answer(
      502,
      JSON.stringify({ error: 'Printer 1 refused the connection (is the controller on?)', gateway: true }),
      { 'X-Shopdeck-Gateway': 'error' },
    );
    await vi.advanceTimersByTimeAsync(0);
    const e = await rejection(run.result);
    expect(e).toBeInstanceOf(LinkError);
    expect(e).not.toBeInstanceOf(CommandNotConfirmed);
    expect(t.ctx.commands.state.getState().last['test.pause']).toMatchObject({ ok: false });
    expect(t.ctx.commands.state.getState().last['test.pause']?.message).toMatch(
      /^Printer 1 refused the connection \(is the controller on\?\) — not sent$/,
    );
  });

  it('a cut answer to a command is "not confirmed", not a failure', async () => {
    const t = setup();
    const run = track(t.ctx.commands.run(t.command(), undefined));
    await vi.advanceTimersByTimeAsync(0);
    f.last().fail();
    await vi.advanceTimersByTimeAsync(0);
    expect(await rejection(run.result)).toBeInstanceOf(CommandNotConfirmed);
  });

  it('a command that transfers a file is a long operation: no overall deadline; its command requests keep theirs', async () => {
    const t = setup();
    const cmd = t.command({
      perform: async (_a, c) => {
        const form = new FormData();
        form.append('file', new Blob(['G1 X1']), 'a.gcode');
        await t.client.raw({
          method: 'POST',
          path: '/upload',
          body: form,
          commandId: c.commandId,
          timeoutMs: 120_000,
        });
        await t.client.raw({ path: '/list', timeoutMs: 30_000 }); // its check: a read
        await t.client.raw({ method: 'POST', path: '/select', commandId: c.commandId });
        return 'uploaded';
      },
    });
    const run = track(t.ctx.commands.run(cmd, undefined));
    await vi.advanceTimersByTimeAsync(0);
    expect(f.last().headers.get('X-Shopdeck-Deadline')).toBeNull();
    await vi.advanceTimersByTimeAsync(30_000);
    expect(run.settled()).toBe(false);
    f.last().answer(200, '{}');
    await vi.advanceTimersByTimeAsync(10_000); // a slow check
    expect(run.settled()).toBe(false);
    f.last().answer(200, '[]');
    await vi.advanceTimersByTimeAsync(0);
    expect(f.calls).toHaveLength(3);
    expect(f.last().headers.get('X-Shopdeck-Deadline')).toBe(String(DEFAULT_COMMAND_DEADLINE_MS));
    f.last().answer(200, '{}');
    await expect(run.result).resolves.toBe('uploaded');
  });

  it('an upload with progress (XMLHttpRequest) is a transfer too', async () => {
    const t = setup();
    const sent: Array<{ headers: Record<string, string>; done: () => void }> = [];
    class FakeXhr {
      status = 0;
      responseText = '';
      timeout = 0;
      upload: { onprogress: ((e: { loaded: number; total: number }) => void) | null } = { onprogress: null };
      onload: (() => void) | null = null;
      onerror: (() => void) | null = null;
      ontimeout: (() => void) | null = null;
      onabort: (() => void) | null = null;
      private readonly headers: Record<string, string> = {};
      open(): void {}
      setRequestHeader(k: string, v: string): void {
        this.headers[k] = v;
      }
      getAllResponseHeaders(): string {
        return 'content-type: application/json\r\n';
      }
      abort(): void {}
      send(): void {
        sent.push({
          headers: this.headers,
          done: () => {
            this.status = 200;
            this.responseText = '{"result":"ok"}';
            this.onload?.();
          },
        });
      }
    }
    vi.stubGlobal('XMLHttpRequest', FakeXhr);
    const cmd = t.command({
      perform: async (_a, c) => {
        await uploadWithProgress({
          method: 'POST',
          url: t.client.url('/upload'),
          body: new Blob(['x']),
          headers: { 'X-Shopdeck-Command': c.commandId },
        });
        return 'uploaded';
      },
    });
    const run = track(t.ctx.commands.run(cmd, undefined));
    await vi.advanceTimersByTimeAsync(60_000);
    expect(run.settled()).toBe(false);
    expect(sent[0]?.headers['X-Shopdeck-Deadline']).toBeUndefined();
    sent[0]?.done();
    await expect(run.result).resolves.toBe('uploaded');
  });

  it('makes what the command declared stale read again when it is not confirmed', async () => {
    const t = setup();
    const invalidate = vi.spyOn(t.ctx.queries, 'invalidate');
    const run = track(t.ctx.commands.run(t.command({ invalidates: [['files']] }), undefined));
    await vi.advanceTimersByTimeAsync(DEFAULT_COMMAND_DEADLINE_MS + DEADLINE_GRACE_MS);
    expect(await rejection(run.result)).toBeInstanceOf(CommandNotConfirmed);
    expect(invalidate).toHaveBeenCalledWith(['files']);
  });
});

describe('commands while the link is in doubt', () => {
  const stop: CommandDecl = {
    id: 'test.stop',
    label: 'Stop',
    hazard: 'stop',
    role: 'operator',
    confirm: false,
    perform: async () => 'stopped',
  };

  it('disables every command but stops while reconnecting, and while the data is stale', () => {
    const t = setup();
    const pause = t.command();
    expect(t.ctx.commands.blockedReason(pause)).toBeNull();
    t.ctx.snapshot.setState({ link: 'reconnecting' });
    expect(t.ctx.commands.blockedReason(pause)).toMatch(/in doubt.*reconnecting/);
    expect(t.ctx.commands.blockedReason(stop)).toBeNull();
    t.ctx.snapshot.setState({ link: 'online', updatedAt: Date.now() });
    expect(t.ctx.commands.blockedReason(pause)).toBeNull();
    expect(t.ctx.commands.msUntilInDoubt()).toBe(IN_DOUBT_AFTER_MS);
    vi.advanceTimersByTime(IN_DOUBT_AFTER_MS + 1);
    expect(t.ctx.commands.blockedReason(pause)).toMatch(/in doubt/);
    expect(t.ctx.commands.blockedReason(stop)).toBeNull();
    expect(t.ctx.commands.msUntilInDoubt()).toBeNull();
    t.ctx.snapshot.setState({ updatedAt: Date.now() });
    expect(t.ctx.commands.blockedReason(pause)).toBeNull();
  });
});

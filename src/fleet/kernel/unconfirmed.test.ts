import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { CommandNotConfirmed, DEADLINE_GRACE_MS } from '../commands';
import { createContext } from '../fleet';
import { alwaysVisible } from '../link';
import type { MachineInfo } from '../types';
import { defineCommands } from './commands';
import { KernelSession } from './session';

/**
 * Issue 15: a command that was not confirmed makes the session read the machine again at once
 * (every family's polls, through the kernel), so the operator sees the machine's actual state
 * before deciding again — not a whole poll interval later.
 */

const info: MachineInfo = { id: 'u1', name: 'U1', kind: 'prunt', simulated: false };

beforeEach(() => {
  vi.useFakeTimers();
});
afterEach(() => {
  vi.useRealTimers();
});

class Session extends KernelSession {
  reads = 0;
  readonly cmds = defineCommands({ snapshot: this.ctx.snapshot });
  readonly pause = this.cmds.define({
    id: 'u.pause',
    label: 'Pause',
    hazard: 'job',
    role: 'operator',
    confirm: false,
    deadlineMs: 1000,
    // Never confirmed (a silent controller).
    perform: () => new Promise<string>(() => undefined),
  });
  readonly commands = this.cmds.all;

  constructor(ctx: ConstructorParameters<typeof KernelSession>[0]) {
    super(ctx);
    this.poll({
      name: 'status',
      read: async () => ++this.reads,
      apply: () => this.tracker.ok(),
      intervalMs: () => 30_000,
    });
  }
}

describe('a command that was not confirmed', () => {
  it('makes every poll run again at once; stopped sessions are left alone', async () => {
    const ctx = createContext(info, {
      visibility: alwaysVisible,
      principal: () => ({ name: 'op', role: 'operator' }),
    });
    const s = new Session(ctx);
    s.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(s.reads).toBe(1);
    let outcome: unknown = null;
    ctx.commands.run(s.pause, undefined).catch((e: unknown) => (outcome = e));
    await vi.advanceTimersByTimeAsync(1000 + DEADLINE_GRACE_MS);
    expect(outcome).toBeInstanceOf(CommandNotConfirmed);
    await vi.advanceTimersByTimeAsync(1);
    expect(s.reads).toBe(2); // at once, not 30 s later
    s.stop();
    ctx.snapshot.setState({ updatedAt: Date.now() });
    ctx.commands.run(s.pause, undefined).catch(() => undefined);
    await vi.advanceTimersByTimeAsync(60_000);
    expect(s.reads).toBe(2);
  });
});

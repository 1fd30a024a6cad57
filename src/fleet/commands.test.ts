import { describe, expect, it } from 'vitest';
import { CommandRefused, confirmationText, type CommandDecl } from './commands';
import { createContext } from './fleet';
import { alwaysVisible } from './link';
import type { Role } from './types';

function setup(role: Role = 'operator') {
  const ctx = createContext(
    { id: 'm1', name: 'M1', kind: 'xtool', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'ann', role }) },
  );
  let sent = 0;
  let release: (() => void) | null = null;
  const pause: CommandDecl = {
    id: 'test.pause',
    label: 'Pause',
    hazard: 'job',
    role: 'operator',
    confirm: false,
    perform: () =>
      new Promise<string>((resolve) => {
        sent++;
        release = () => resolve('paused');
      }),
  };
  return { ctx, pause, sent: () => sent, release: () => (release as unknown as () => void)() };
}

describe('CommandRunner', () => {
  it('never sends (or queues) a command while the machine is not online', async () => {
    const t = setup();
    t.ctx.snapshot.setState({ link: 'reconnecting' });
    await expect(t.ctx.commands.run(t.pause, undefined)).rejects.toBeInstanceOf(CommandRefused);
    // Coming back online does not replay it.
    t.ctx.snapshot.setState({ link: 'online' });
    await Promise.resolve();
    expect(t.sent()).toBe(0);
    expect(t.ctx.log.store.getState().entries.at(-1)?.text).toContain('not sent');
  });

  it('still tries a stop once while the link is down, and never retries it', async () => {
    const t = setup();
    t.ctx.snapshot.setState({ link: 'reconnecting' });
    let attempts = 0;
    const estop: CommandDecl = {
      id: 'test.estop',
      label: 'Emergency stop',
      hazard: 'stop',
      role: 'operator',
      confirm: false,
      perform: async () => {
        attempts++;
        throw new Error('Cannot reach the controller');
      },
    };
    await expect(t.ctx.commands.run(estop, undefined)).rejects.toThrow('Cannot reach');
    t.ctx.snapshot.setState({ link: 'online' });
    await Promise.resolve();
    expect(attempts).toBe(1);
    // A job command is still refused while the link is down.
    t.ctx.snapshot.setState({ link: 'offline' });
    await expect(t.ctx.commands.run(t.pause, undefined)).rejects.toBeInstanceOf(CommandRefused);
  });

  it('cannot send the same command twice while it is in flight', async () => {
    const t = setup();
    t.ctx.snapshot.setState({ link: 'online' });
    const first = t.ctx.commands.run(t.pause, undefined);
    expect(t.ctx.commands.state.getState().inFlight['test.pause']).toBe(true);
    await expect(t.ctx.commands.run(t.pause, undefined)).rejects.toThrow('Already being sent');
    t.release();
    await expect(first).resolves.toBe('paused');
    expect(t.sent()).toBe(1);
    expect(t.ctx.commands.state.getState().inFlight['test.pause']).toBeUndefined();
    expect(t.ctx.commands.state.getState().last['test.pause']?.ok).toBe(true);
  });

  it('refuses a command above the user role and says which role is needed', async () => {
    const t = setup('viewer');
    t.ctx.snapshot.setState({ link: 'online' });
    await expect(t.ctx.commands.run(t.pause, undefined)).rejects.toThrow(/operator/);
    expect(t.sent()).toBe(0);
  });

  it('respects the availability predicate', async () => {
    const t = setup();
    t.ctx.snapshot.setState({ link: 'online', activity: 'idle' });
    const cmd: CommandDecl = {
      ...t.pause,
      available: (s) => (s.activity === 'running' ? true : 'Nothing is running'),
    };
    expect(t.ctx.commands.blockedReason(cmd)).toBe('Nothing is running');
  });

  it('asks confirmation for job and dangerous commands unless told otherwise', () => {
    const base = { id: 'x', label: 'Start job', role: 'operator' as const, perform: async () => undefined };
    expect(confirmationText({ ...base, hazard: 'job' }, undefined)).toBe('Start job?');
    expect(confirmationText({ ...base, hazard: 'dangerous' }, undefined)).toMatch(/dangerous/);
    expect(confirmationText({ ...base, hazard: 'read' }, undefined)).toBeNull();
    expect(confirmationText({ ...base, hazard: 'stop', confirm: false }, undefined)).toBeNull();
    expect(confirmationText({ ...base, hazard: 'stop', confirm: 'Stop the job?' }, undefined)).toBe(
      'Stop the job?',
    );
  });
});

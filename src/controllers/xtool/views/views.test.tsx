// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen } from '@testing-library/react';
import { afterEach, beforeEach, describe, expect, it } from 'vitest';
import { authStore } from '../../../fleet/auth';
import { createContext } from '../../../fleet/fleet';
import type { CommandDecl } from '../../../fleet/commands';
import type { SessionContext } from '../../../fleet/contract';
import { useBlockedReason } from '../../../fleet/kernel';
import { CommandButton } from '../../../fleet/react';
import { alwaysVisible } from '../../../fleet/link';
import type { Role } from '../../../fleet/types';
import { SETTINGS_KEY } from '../queries';
import { XtoolSession, type UploadArgs, type XtoolSettings } from '../session';
import type { PeripheryStatus } from '../wire';
import { Discover } from './Discover';
import { Overview } from './Overview';
import { Safety } from './Safety';

/**
 * The machine page: the family's job commands (shown by the page's shared job control row,
 * src/app/kiosk/JobControls.tsx, which a family may not import) over the family's overview.
 */
function Page({ session }: { session: XtoolSession }) {
  const { commands: runner, snapshot } = session.ctx;
  return (
    <>
      {[session.pause, session.resume, session.stopJob].map((c) => (
        <CommandButton key={c.id} runner={runner} snapshot={snapshot} command={c} args={undefined} />
      ))}
      <Overview session={session} />
    </>
  );
}

/** A session that is never started: the tests feed it frames and state directly (no network). */
function online(role: Role) {
  authStore.setState({ mode: 'secured', user: { name: 't', role, machines: null } });
  const ctx = createContext(
    { id: 'v1', name: 'Laser', kind: 'xtool', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role }) },
  );
  const session = new XtoolSession(ctx);
  ctx.snapshot.setState({ link: 'online' });
  session.detail.setState({ model: { family: 'd-series', answered: [] } });
  return { ctx, session };
}

/** The Safety tab shows the settings read (an on-demand read): put one answer in the query layer. */
function settingsRead(session: XtoolSession, periphery: PeripheryStatus): void {
  const answer: XtoolSettings = { periphery, offset: null, dotMode: null };
  session.ctx.queries.set(SETTINGS_KEY, answer);
}

beforeEach(() => authStore.setState({ mode: 'unknown', user: null }));
afterEach(() => cleanup());

/** A command button the user cannot use now: disabled while in flight, aria-disabled when unavailable. */
function unavailable(el: HTMLElement): boolean {
  return (el as HTMLButtonElement).disabled || el.getAttribute('aria-disabled') === 'true';
}

describe('Overview', () => {
  it('shows the loaded job plainly and enables only what makes sense', () => {
    const { session } = online('operator');
    render(<Page session={session} />);
    act(() => session.onFrame('ok:WORKING_ONLINE_READY\n'));
    expect(screen.getByTestId('xtool-press-button').textContent).toMatch(/button on the machine/);
    expect(unavailable(screen.getByTestId('cmd-xtool.pause'))).toBe(true);
    expect(unavailable(screen.getByTestId('cmd-xtool.stop'))).toBe(false);

    act(() => session.onFrame('ok:WORKING_ONLINE\n'));
    expect(screen.getByTestId('xtool-state').textContent).toBe('running');
    expect(unavailable(screen.getByTestId('cmd-xtool.pause'))).toBe(false);
    expect(unavailable(screen.getByTestId('cmd-xtool.resume'))).toBe(true);

    fireEvent.click(screen.getByTestId('cmd-xtool.stop'));
    expect(screen.getByTestId('confirm-dialog').textContent).toMatch(/Stop the job\?/);
  });

  it('a viewer sees the state but cannot pause', () => {
    const { session } = online('viewer');
    render(<Page session={session} />);
    act(() => session.onFrame('ok:WORKING_OFFLINE\n'));
    const pause = screen.getByTestId('cmd-xtool.pause') as HTMLButtonElement;
    expect(unavailable(pause)).toBe(true);
    expect(pause.title).toMatch(/operator/);
    // The reason is text beside the button too (shown under it on touch screens).
    expect(screen.getByTestId('cmd-reason-xtool.pause').textContent).toMatch(/operator/);
  });

  it('says "unsupported model" with what the device answered', () => {
    const { session } = online('viewer');
    session.detail.setState({
      model: { family: 'unsupported', answered: ['/getmachinetype → type "xTool S1"'] },
    });
    render(<Overview session={session} />);
    expect(screen.getByTestId('xtool-unsupported').textContent).toMatch(/xTool S1/);
  });
});

describe('Safety', () => {
  it('warns when a sensor is off and confirms turning the flame alarm off', () => {
    const { session } = online('supervisor');
    settingsRead(session, {
      result: 'ok',
      tiltStopFlag: false,
      limitStopFlag: true,
      movingStopFlag: true,
      flameAlarmSensitivity: 1,
    });
    render(<Safety session={session} />);
    expect(screen.getByTestId('xtool-safety-off')).toBeTruthy();
    fireEvent.click(screen.getByTestId('cmd-xtool.flame-alarm-off'));
    expect(screen.getByTestId('confirm-dialog').textContent).toMatch(/catches fire/);
  });

  it('an operator cannot change safety settings', () => {
    const { session } = online('operator');
    settingsRead(session, { result: 'ok', tiltStopFlag: true, flameAlarmSensitivity: 1 });
    render(<Safety session={session} />);
    expect(unavailable(screen.getByTestId('cmd-xtool.tilt-stop-off'))).toBe(true);
    expect(unavailable(screen.getByTestId('cmd-xtool.flame-alarm-off'))).toBe(true);
  });
});

describe('availability follows the family store (issue 12, defect 3)', () => {
  /** What a command button shows: the reason it is blocked, kept current (useBlockedReason). */
  function Blocked({ ctx, command }: { ctx: SessionContext; command: CommandDecl<UploadArgs> }) {
    const reason = useBlockedReason(ctx.commands, ctx.snapshot, command);
    return <output data-testid="blocked">{reason ?? 'available'}</output>;
  }

  it('upload says "no SD card" as soon as the settings say so, with no snapshot change', () => {
    const { ctx, session } = online('operator');
    session.detail.setState({
      machine: { state: 'idle', startedBy: null, sensor: null },
      periphery: { result: 'ok', sdCard: true },
    });
    render(<Blocked ctx={ctx} command={session.upload} />);
    const shown = () => screen.getByTestId('blocked').textContent;
    expect(shown()).toBe('available');
    const snap = ctx.snapshot.getState();
    act(() => session.detail.setState({ periphery: { result: 'ok', sdCard: false } }));
    expect(ctx.snapshot.getState()).toBe(snap); // only the family store changed
    expect(shown()).toBe('No SD card in the laser');
    act(() => session.detail.setState({ machine: { state: 'running', startedBy: 'button', sensor: null } }));
    expect(shown()).toBe('The laser is busy with a job');
    act(() =>
      session.detail.setState({
        machine: { state: 'idle', startedBy: null, sensor: null },
        periphery: { result: 'ok', sdCard: true },
      }),
    );
    expect(shown()).toBe('available');
  });
});

describe('Discover', () => {
  it('lists the lasers that answered and the machines-file entries to add', async () => {
    const answer = {
      replies: [{ requestId: 1, ip: '127.0.0.1', name: 'xTool D1 Pro', version: '40.31.006.01', via: 'udp' }],
      broadcast: '127.0.0.1',
    };
    const real = globalThis.fetch;
    const urls: string[] = [];
    globalThis.fetch = (input: RequestInfo | URL) => {
      urls.push(String(input));
      return Promise.resolve(new Response(JSON.stringify(answer)));
    };
    try {
      render(<Discover />);
      await act(async () => {
        fireEvent.click(screen.getByTestId('xtool-discover-search'));
        await Promise.resolve();
      });
      await screen.findByTestId('xtool-discover-table');
      expect(urls[0]).toMatch(/\/api\/discover\/xtool$/);
      expect(screen.getByTestId('xtool-discover-table').textContent).toMatch(/127\.0\.0\.1/);
      expect(JSON.parse(screen.getByTestId('xtool-discover-entries').textContent ?? '')).toEqual({
        id: 'xtool-d1-pro',
        name: 'xTool D1 Pro',
        kind: 'xtool',
        url: 'http://127.0.0.1:8080',
      });
    } finally {
      globalThis.fetch = real;
    }
  });
});

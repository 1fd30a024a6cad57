// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen, waitFor, within } from '@testing-library/react';
import { afterEach, beforeAll, describe, expect, it, vi } from 'vitest';
import { registerController } from '../controllers';
import type { ControllerModule, MachineSession, SessionContext } from '../fleet/contract';
import { createRuntime, fleetStore, registerRuntime, type MachineRuntime } from '../fleet/fleet';
import { authStore } from '../fleet/auth';
import { alwaysVisible } from '../fleet/link';
import type { MachineInfo } from '../fleet/types';

/**
 * Issue 12: the page structure a screen reader and a keyboard rely on. A fleet tile has one link
 * (the machine's name) and no clickable container; the machine's sections are links in a
 * navigation with aria-current (they are URLs), not tabs; a blocking alarm is a modal alert
 * dialog and the page behind it is inert.
 */

const acknowledged: string[] = [];

function fakeModule(): ControllerModule {
  return {
    kind: 'duet',
    label: 'Fake printer',
    createSession: (ctx: SessionContext): MachineSession => ({
      machine: ctx.machine,
      ctx,
      commands: {},
      start: () => undefined,
      stop: () => undefined,
      acknowledgeAlarm: (id: string) => {
        acknowledged.push(id);
        ctx.snapshot.setState({ alarms: [] });
      },
    }),
    tabs: [
      { id: 'overview', label: 'Overview', Component: () => <p>overview body</p> },
      { id: 'files', label: 'Files', Component: () => <p>files body</p> },
    ],
  };
}

const duetModule = fakeModule();
registerController(duetModule);

const { App } = await import('./App');
const { FleetPage } = await import('./FleetPage');
const { MachinePage } = await import('./MachinePage');

const MILL: MachineInfo = { id: 'mill', name: 'Mill one', kind: 'duet', simulated: false };
let rt: MachineRuntime;

beforeAll(() => {
  rt = createRuntime(MILL, (c) => duetModule.createSession(c), { visibility: alwaysVisible });
  registerRuntime(rt);
  rt.session?.start();
  rt.snapshot.setState({ link: 'online', activity: 'idle', activityLabel: 'Idle', updatedAt: Date.now() });
  fleetStore.setState({ status: 'ready', machines: [MILL], error: null });
});

afterEach(() => {
  cleanup();
  history.replaceState(null, '', '/');
});

describe('fleet tile', () => {
  it('is an article named by the machine, with one link (its name) to the machine page', () => {
    render(<FleetPage />);
    const tile = screen.getByRole('article', { name: 'Mill one' });
    const links = within(tile).getAllByRole('link');
    expect(links).toHaveLength(1);
    expect(links[0]?.textContent).toBe('Mill one');
    expect(links[0]?.getAttribute('href')).toBe('/m/mill');
    expect(tile.getAttribute('role')).toBeNull();
    expect(tile.hasAttribute('tabindex')).toBe(false);
  });
});

describe('machine sections', () => {
  it('are links in a "Machine sections" navigation, the current one with aria-current="page"', () => {
    history.replaceState(null, '', '/m/mill/files');
    render(<MachinePage id="mill" tab="files" />);
    const nav = screen.getByRole('navigation', { name: 'Machine sections' });
    const files = within(nav).getByRole('link', { name: 'Files' });
    const overview = within(nav).getByRole('link', { name: 'Overview' });
    expect(files.getAttribute('aria-current')).toBe('page');
    expect(overview.getAttribute('aria-current')).toBeNull();
    expect(overview.getAttribute('href')).toBe('/m/mill/overview');
    expect(screen.queryAllByRole('tab')).toHaveLength(0);
    expect(screen.queryAllByRole('tablist')).toHaveLength(0);
    fireEvent.click(overview);
    expect(location.pathname).toBe('/m/mill/overview');
  });
});

describe('blocking alarm', () => {
  it('is a modal alert dialog named "Critical alarm"; the page behind is inert until it is acknowledged', async () => {
    // The gateway: an empty alarm list until its watch has recorded the flame, then the record;
    // the acknowledgement taken by the record's id.
    const posted: unknown[] = [];
    const flame = {
      id: '7',
      machine: 'mill',
      machineName: 'Mill',
      family: 'duet',
      key: 'flame',
      severity: 'critical',
      text: 'FLAME DETECTED',
      blocking: true,
      since: Date.now(),
      clearedAt: null,
      ackBy: null as string | null,
      ackAt: null as number | null,
    };
    let recorded = false;
    let version = 1;
    // Signed in (open mode): the page reads the alarm list.
    authStore.setState({ mode: 'open', user: null });
    vi.stubGlobal(
      'fetch',
      vi.fn((url: string, init?: RequestInit) => {
        if (init?.method === 'POST') {
          posted.push([url, JSON.parse(String(init.body))]);
          Object.assign(flame, { ackBy: 'otto', ackAt: Date.now() });
          version++;
        }
        const body = url.startsWith('/api/alarms/ack')
          ? { alarm: flame }
          : { version, alarms: recorded ? [{ ...flame }] : [] };
        return Promise.resolve(new Response(JSON.stringify(body), { status: 200 }));
      }),
    );
    render(<App />);
    const page = screen.getByTestId('app-page');
    expect(page.hasAttribute('inert')).toBe(false);
    act(() =>
      rt.snapshot.setState({
        alarms: [
          { id: 'flame', severity: 'critical', message: 'FLAME DETECTED', since: Date.now(), blocking: true },
        ],
      }),
    );
    // The alarm layer loads once the browser is idle (its own chunk).
    const alarm = await screen.findByRole('alertdialog', { name: 'Critical alarm' }, { timeout: 5000 });
    expect(alarm.tagName).toBe('DIALOG');
    expect(alarm.textContent).toContain('FLAME DETECTED');
    await waitFor(() => expect(page.hasAttribute('inert')).toBe(true));
    expect(page.contains(alarm)).toBe(false);
    // Read first: focus on the dialog, not on the acknowledgement.
    expect(document.activeElement).toBe(alarm);
    // Escape does not dismiss it.
    act(() => {
      alarm.dispatchEvent(new Event('cancel', { cancelable: true }));
    });
    expect(screen.getByRole('alertdialog', { name: 'Critical alarm' })).toBe(alarm);

    // The console records the flame (its watch saw it too); the page may not have read it yet.
    recorded = true;
    version++;
    fireEvent.click(within(alarm).getByRole('button', { name: /acknowledge/ }));
    // Recorded at the gateway (who and when) by the record's id: never in advance by a key.
    await waitFor(() => expect(posted).toEqual([['/api/alarms/ack', { id: '7' }]]));
    await waitFor(() => expect(acknowledged).toEqual(['flame']));
    await waitFor(() => expect(screen.queryByRole('alertdialog')).toBeNull());
    vi.unstubAllGlobals();
    authStore.setState({ mode: 'unknown', user: null });
    await waitFor(() => expect(page.hasAttribute('inert')).toBe(false));
  });
});

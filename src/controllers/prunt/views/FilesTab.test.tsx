// @vitest-environment happy-dom
import { cleanup, render, screen, waitFor } from '@testing-library/react';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it } from 'vitest';
import { createContext } from '../../../fleet/fleet';
import { alwaysVisible } from '../../../fleet/link';
import { simulatorHandlers } from '../../../fleet/msw';
import { memoryDraftStorage } from '../../../forms/storage';
import { PruntSession } from '../session';
import { PruntSimulator } from '../sim/sim';
import { FilesTab, UpdateLink } from './FilesTab';

const server = setupServer();
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());

let sim: PruntSimulator;
let session: PruntSession;
beforeEach(() => {
  sim = new PruntSimulator({ id: 'pf', name: 'pf', api: 'module', tickMs: 1000 });
  server.resetHandlers(...simulatorHandlers('pf', sim));
  const ctx = createContext(
    { id: 'pf', name: 'Printer', kind: 'prunt', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role: 'operator' }) },
  );
  session = new PruntSession(ctx, { drafts: memoryDraftStorage() });
});
afterEach(() => {
  cleanup();
  session.stop();
  sim.dispose();
});

/** What the page shows for an "update available" URL: the link's href, or null for plain text. */
function shown(url: string): {
  href: string | null;
  text: string;
  rel: string | null;
  target: string | null;
} {
  render(<UpdateLink url={url} />);
  const el = screen.queryByTestId('prunt-update-url');
  const a = el?.closest('a') ?? null;
  const out = {
    href: a?.getAttribute('href') ?? null,
    text: el?.textContent ?? document.body.textContent ?? '',
    rel: a?.getAttribute('rel') ?? null,
    target: a?.getAttribute('target') ?? null,
  };
  cleanup();
  return out;
}

describe('the Prunt "update available" URL', () => {
  it('is a link only to an external https page, opened without opener or referrer', () => {
    expect(shown('https://github.com/Prunt3D/prunt/releases/tag/v2')).toEqual({
      href: 'https://github.com/Prunt3D/prunt/releases/tag/v2',
      text: 'https://github.com/Prunt3D/prunt/releases/tag/v2',
      rel: 'noopener noreferrer',
      target: '_blank',
    });
  });

  it.each([
    ['/machines/acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1'],
    ['%2e%2e/acc-laser/system?action=stop'],
    ['/api/users'],
    ['http://localhost:3000/machines/g2/machine/panic'],
    ['https://localhost:3000/api/users'],
    ['http://github.com/Prunt3D/prunt'],
    ['javascript:alert(document.cookie)'],
    ['java\tscript:alert(1)'],
    ['data:text/html,<script>alert(1)</script>'],
    ['//evil.com/x'],
    ['https://192.168.1.20/system?action=stop'],
  ])('shows %j as plain text, never as a link', (url) => {
    const r = shown(url);
    expect(r.href).toBeNull();
    expect(r.text).toBe(url);
    expect(document.querySelector('a')).toBeNull();
  });

  it('says so when there is no URL', () => {
    expect(shown('').text).toBe('no link given');
  });

  it('in the Files tab: an unsafe URL from the controller is text, a safe one a link', async () => {
    session.store.setState({
      update: { result: { Available: true, URL: '/machines/g2/machine/panic' }, error: null },
    });
    const { unmount } = render(<FilesTab session={session} />);
    await screen.findByText('benchy.gcode');
    expect(screen.getByTestId('prunt-update-url').tagName).toBe('SPAN');
    expect(document.querySelector('a[href*="panic"]')).toBeNull();
    unmount();
    session.store.setState({
      update: { result: { Available: true, URL: 'https://prunt3d.com/update' }, error: null },
    });
    render(<FilesTab session={session} />);
    const a = screen.getByTestId('prunt-update-url');
    expect(a.getAttribute('href')).toBe('https://prunt3d.com/update');
    expect(a.getAttribute('rel')).toBe('noopener noreferrer');
  });
});

describe('Prunt download links', () => {
  it('link files in uploads/ and offer no link for names that would leave it', async () => {
    sim.uploads.set('..', 'x');
    sim.uploads.set('../../acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1', 'x');
    sim.uploads.set('%2e%2e', 'x');
    render(<FilesTab session={session} />);
    await waitFor(() => expect(screen.getByTestId('download-benchy.gcode')).toBeTruthy());
    expect(screen.getByTestId('download-benchy.gcode').getAttribute('href')).toBe(
      'http://shopdeck.test/machines/pf/uploads/benchy.gcode',
    );
    expect(screen.getByTestId('download-..').tagName).toBe('SPAN');
    expect(
      screen.getByTestId('download-../../acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1').tagName,
    ).toBe('SPAN');
    expect(screen.getByTestId('download-%2e%2e').getAttribute('href')).toBe(
      'http://shopdeck.test/machines/pf/uploads/%252e%252e',
    );
    for (const a of document.querySelectorAll('a[href]')) {
      const u = new URL(a.getAttribute('href') ?? '', 'http://shopdeck.test/');
      expect(u.pathname.startsWith('/machines/pf/uploads/')).toBe(true);
    }
  });
});

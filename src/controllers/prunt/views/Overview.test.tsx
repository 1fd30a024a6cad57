// @vitest-environment happy-dom
import { cleanup, render, screen } from '@testing-library/react';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it } from 'vitest';
import { createContext } from '../../../fleet/fleet';
import { alwaysVisible } from '../../../fleet/link';
import { simulatorHandlers } from '../../../fleet/msw';
import { memoryDraftStorage } from '../../../forms/storage';
import { PruntSession } from '../session';
import { PruntSimulator } from '../sim/sim';
import { OverviewTab } from './Overview';

const server = setupServer();
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());

let sim: PruntSimulator;
let session: PruntSession;
beforeEach(() => {
  sim = new PruntSimulator({ id: 'po', name: 'po', api: 'module', tickMs: 1000 });
  server.resetHandlers(...simulatorHandlers('po', sim));
  const ctx = createContext(
    { id: 'po', name: 'Printer', kind: 'prunt', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role: 'operator' }) },
  );
  session = new PruntSession(ctx, { drafts: memoryDraftStorage() });
});
afterEach(() => {
  cleanup();
  session.stop();
  sim.dispose();
});

describe('the Overview tab "update available" notice', () => {
  it('shows a controller URL into the console (another machine) as text, not a link', () => {
    session.store.setState({
      update: {
        result: {
          Available: true,
          URL: '/machines/acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1',
        },
        error: null,
      },
    });
    render(<OverviewTab session={session} />);
    const el = screen.getByTestId('prunt-update-url');
    expect(el.tagName).toBe('SPAN');
    expect(el.textContent).toBe('/machines/acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1');
    expect(document.querySelector('a[href*="acc-laser"]')).toBeNull();
  });

  it('shows javascript: as text', () => {
    session.store.setState({
      update: { result: { Available: true, URL: 'javascript:alert(1)' }, error: null },
    });
    render(<OverviewTab session={session} />);
    expect(screen.getByTestId('prunt-update-url').tagName).toBe('SPAN');
    expect(document.querySelector('a[href^="javascript"]')).toBeNull();
  });

  it('links an external https page with rel="noopener noreferrer"', () => {
    session.store.setState({
      update: { result: { Available: true, URL: 'https://github.com/Prunt3D/prunt/releases' }, error: null },
    });
    render(<OverviewTab session={session} />);
    const a = screen.getByTestId('prunt-update-url');
    expect(a.tagName).toBe('A');
    expect(a.getAttribute('href')).toBe('https://github.com/Prunt3D/prunt/releases');
    expect(a.getAttribute('rel')).toBe('noopener noreferrer');
    expect(a.getAttribute('target')).toBe('_blank');
  });
});

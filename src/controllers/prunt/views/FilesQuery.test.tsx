// @vitest-environment happy-dom
import { act, cleanup, render, screen, waitFor } from '@testing-library/react';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it } from 'vitest';
import { createContext } from '../../../fleet/fleet';
import { alwaysVisible } from '../../../fleet/link';
import { simulatorHandlers } from '../../../fleet/msw';
import { setApiOrigin } from '../../../fleet/origin';
import { memoryDraftStorage } from '../../../forms/storage';
import { PRUNT_KEYS } from '../queries';
import { PruntSession } from '../session';
import { PruntSimulator } from '../sim/sim';
import { FilesTab } from './FilesTab';

const server = setupServer();
const listed: string[] = [];
server.events.on('request:start', ({ request }) => {
  if (request.method === 'GET' && new URL(request.url).pathname.endsWith('/uploads/'))
    listed.push(request.url);
});
beforeAll(() => {
  setApiOrigin('http://shopdeck.test');
  server.listen({ onUnhandledRequest: 'error' });
});
afterAll(() => server.close());

let sim: PruntSimulator;
let session: PruntSession;
beforeEach(() => {
  listed.splice(0);
  sim = new PruntSimulator({ id: 'pq', name: 'pq', api: 'module', tickMs: 1000 });
  server.resetHandlers(...simulatorHandlers('pq', sim));
  const ctx = createContext(
    { id: 'pq', name: 'Printer', kind: 'prunt', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role: 'operator' }) },
  );
  ctx.snapshot.setState({ link: 'online', activity: 'idle' });
  session = new PruntSession(ctx, { drafts: memoryDraftStorage() });
});
afterEach(() => {
  cleanup();
  session.stop();
  sim.dispose();
});

describe('the Prunt file list is an on-demand read', () => {
  it('is read once, kept per machine, and read again after an upload (the command invalidates it)', async () => {
    const { unmount } = render(<FilesTab session={session} />);
    await screen.findByText('benchy.gcode');
    expect(listed).toHaveLength(1);
    expect(session.ctx.queries.peek<string[]>(PRUNT_KEYS.files)).toContain('benchy.gcode');
    // Shown again within its stale time: from the cache, no second request.
    unmount();
    render(<FilesTab session={session} />);
    expect(screen.getByText('benchy.gcode')).toBeTruthy();
    expect(listed).toHaveLength(1);
    await act(async () => {
      await session.ctx.commands.run(session.cmd.upload, { name: 'new part.gcode', body: 'G28\n' });
    });
    await waitFor(() => expect(screen.getByTestId('download-new part.gcode')).toBeTruthy());
    expect(listed).toHaveLength(2);
    // The one upload state: done, with the file's name.
    expect(session.uploads.state.phase).toBe('done');
    expect(screen.getByTestId('prunt-upload').getAttribute('data-phase')).toBe('done');
  });
});

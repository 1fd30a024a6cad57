// @vitest-environment happy-dom
import { setupServer } from 'msw/node';
import { afterAll, beforeAll, describe, expect, it } from 'vitest';
import { simulatorHandlers } from '../../fleet/msw';
import { setApiOrigin } from '../../fleet/origin';
import { PruntClient } from './client';
import { PruntSimulator } from './sim/sim';

const sim = new PruntSimulator({ id: 'up', name: 'up', api: 'module', tickMs: 1000 });
const server = setupServer(...simulatorHandlers('up', sim));
beforeAll(() => {
  setApiOrigin('http://shopdeck.test');
  server.listen({ onUnhandledRequest: 'error' });
});
afterAll(() => {
  server.close();
  sim.dispose();
});

describe('upload with progress (PUT /uploads/<name>)', () => {
  it('stores the file on the controller, reports progress and sends the command header', async () => {
    let header: string | null = null;
    server.events.on('request:start', ({ request }) => {
      if (request.method === 'PUT') header = request.headers.get('X-Shopdeck-Command');
    });
    const client = new PruntClient('up');
    const seen: number[] = [];
    await client.upload('part.gcode', 'G28\nG1 X10\n', {
      commandId: 'prunt.upload',
      onProgress: (p) => seen.push(p.loaded),
    });
    expect(sim.uploads.get('part.gcode')).toBe('G28\nG1 X10\n');
    expect(header).toBe('prunt.upload');
    expect(await client.uploads()).toContain('part.gcode');
  });
});

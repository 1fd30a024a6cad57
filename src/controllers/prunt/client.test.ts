import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, describe, expect, it } from 'vitest';
import { LinkError } from '../../fleet/errors';
import { simulatorHandlers } from '../../fleet/msw';
import { PruntClient } from './client';
import { PruntSimulator } from './sim/sim';

const sim = new PruntSimulator({ id: 'p1', name: 'p1', api: 'module', tickMs: 1000 });
const server = setupServer(...simulatorHandlers('p1', sim));
const requested: string[] = [];
server.events.on('request:start', ({ request }) => void requested.push(`${request.method} ${request.url}`));
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterEach(() => void requested.splice(0));
afterAll(() => {
  server.close();
  sim.dispose();
});

const UPLOADS = 'http://shopdeck.test/machines/p1/uploads/';

describe('Prunt file URLs stay in /machines/<id>/uploads/', () => {
  const c = new PruntClient('p1');

  it('gives ordinary names (spaces, %, unicode) a URL in the uploads folder', () => {
    expect(c.fileUrl('benchy.gcode')).toBe(`${UPLOADS}benchy.gcode`);
    expect(c.fileUrl('my part (v2).gcode')).toBe(`${UPLOADS}my%20part%20(v2).gcode`);
    expect(c.fileUrl('50%.gcode')).toBe(`${UPLOADS}50%25.gcode`);
    expect(c.fileUrl('Ärger.gcode')).toBe(`${UPLOADS}%C3%84rger.gcode`);
    expect(c.fileUrl('a..b.gcode')).toBe(`${UPLOADS}a..b.gcode`);
    // A file literally named "%2e%2e": encoded once more, it stays a name in uploads/.
    expect(c.fileUrl('%2e%2e')).toBe(`${UPLOADS}%252e%252e`);
  });

  it.each([
    ['..'],
    ['.'],
    [''],
    ['../../acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1'],
    ['../config/values'],
    ['..\\..\\api\\users'],
    ['sub/part.gcode'],
    ['a\u0000.gcode'],
  ])('refuses the name %j (no URL outside, no encoded way out)', (name) => {
    expect(c.fileUrl(name)).toBeNull();
  });

  it('never sends a download or an upload for a refused name', async () => {
    await expect(c.download('..')).rejects.toMatchObject({ kind: 'protocol' });
    await expect(c.download('../../acc-laser/system?x')).rejects.toBeInstanceOf(LinkError);
    await expect(c.upload('..', 'G28', { commandId: 'prunt.upload' })).rejects.toMatchObject({
      kind: 'protocol',
    });
    expect(requested).toEqual([]);
  });

  it('still downloads an ordinary file', async () => {
    const blob = await c.download('benchy.gcode');
    expect(await blob.text()).toBe(sim.uploads.get('benchy.gcode'));
    expect(requested).toEqual([`GET ${UPLOADS}benchy.gcode`]);
  });
});

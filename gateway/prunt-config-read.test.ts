import { afterEach, describe, expect, it } from 'vitest';
import { pruntFamily } from '../src/controllers/prunt/family';
import { consoleFetch, gatewayFor, stubEntry, stubFor, type Cleanups } from './test-util';

const cleanups: Cleanups = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

/**
 * Issue 33 (13): opening Prunt's config editor wrote audit entries, because the gateway took
 * `GET /config/values` for a command ("it rewrites the config file on 2025 boards"). Prunt's
 * `Get_Values` (prunt-config.adb) only reads: the file is written once, at the first access after
 * Prunt starts (`Maybe_Do_Init`), and by a save (`Patch`). A read is a read: not audited; a save
 * still is. On a real controller (a stub on a socket) and on the demo fleet's simulated one (the
 * 2025 flat API, answered inside the gateway).
 */
describe('Prunt: reading the config is not a command', () => {
  it('GET /config/values is answered and writes no audit entry; POST /config/values (a save) is audited', async () => {
    const s = await stubFor(cleanups);
    s.respond = (_req, res) => {
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end('{"Values":{},"Errors":[]}');
    };
    const gw = await gatewayFor(
      cleanups,
      [
        stubEntry('p-real', s.url),
        stubEntry('p-flat-2025', null, { simulated: true }),
        stubEntry('p-module', null, { simulated: true }),
      ],
      { families: { prunt: pruntFamily } },
    );
    const commands = () => gw.gw.audit.all().filter((e) => e.type === 'command');
    for (const id of ['p-real', 'p-flat-2025', 'p-module']) {
      for (const path of ['/config/schema', '/config/values', '/config/values']) {
        const r = await consoleFetch(`${gw.url}/machines/${id}${path}`);
        expect(r.status, `${id} ${path}`).toBe(200);
        await r.arrayBuffer();
      }
    }
    expect(s.seen.filter((q) => q.url === '/config/values')).toHaveLength(2);
    // Opening the editor three times over: nothing in the audit log.
    expect(commands()).toEqual([]);
    expect(gw.gw.audit.all().filter((e) => e.machine === 'p-real' || e.machine === 'p-flat-2025')).toEqual(
      [],
    );

    // A save is a command, audited before it is sent.
    const r = await consoleFetch(`${gw.url}/machines/p-real/config/values`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json' },
      body: '{"Fans$FAN_2$PWM frequency":200}',
    });
    expect(r.status).toBe(200);
    expect(commands()).toEqual([
      expect.objectContaining({ machine: 'p-real', path: '/config/values', result: 'ok' }),
    ]);
  });
});

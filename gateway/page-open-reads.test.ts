import { afterEach, describe, expect, it } from 'vitest';
import { families } from '../src/controllers/families';
import type { MachineEntry } from './machines';
import { gatewayFor, stubFor, type Cleanups, type Stub } from './test-util';

/**
 * Page-open reads shared across tabs (issue 34): five tabs that open one machine's page at the
 * same moment ask its controller once for each read every page makes when it opens (Prunt's
 * status schema and update check, the xTool's identity), through the real gateway on real
 * sockets, for a controller and for a simulated machine alike.
 */

const cleanups: Cleanups = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

function machine(id: string, kind: MachineEntry['kind'], url: string | null): MachineEntry {
  return {
    id,
    name: id,
    kind,
    simulated: url === null,
    url: url ? new URL(url) : null,
    wsUrl: null,
    secrets: {},
  };
}

/** A controller that answers after a while, so the tabs' reads overlap as on a real network. */
async function slowStub(): Promise<Stub> {
  const stub = await stubFor(cleanups);
  stub.respond = (req, res) => {
    setTimeout(() => {
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ ok: true, path: req.url }));
    }, 150);
  };
  return stub;
}

const TABS = 5;

async function openTabs(base: string, id: string, reads: readonly string[]): Promise<number[]> {
  const all = await Promise.all(
    Array.from({ length: TABS }, () =>
      Promise.all(
        reads.map(async (p) => {
          const r = await fetch(`${base}/machines/${id}${p}`);
          await r.arrayBuffer();
          return r.status;
        }),
      ),
    ),
  );
  return all.flat();
}

const PRUNT_OPEN = ['/status/schema', '/update-check'];
const XTOOL_OPEN = [
  '/getmachinetype',
  '/getlaserpowertype',
  '/getlaserpowerinfo',
  '/system?action=version',
  '/system?action=mac',
  '/system?action=get_dev_name',
];

describe('page-open reads: five tabs, one request each', () => {
  it('Prunt: five tabs opening at once read the status schema and the update check once', async () => {
    const stub = await slowStub();
    const gw = await gatewayFor(cleanups, [machine('printer', 'prunt', stub.url)], { families });
    const statuses = await openTabs(gw.url, 'printer', PRUNT_OPEN);
    expect(statuses).toEqual(statuses.map(() => 200));
    for (const p of PRUNT_OPEN) expect(stub.seen.filter((s) => s.url === p).length, p).toBe(1);
    expect(gw.gw.upstreamStats('printer')?.sharedAnswers).toBe((TABS - 1) * PRUNT_OPEN.length);
    // What follows a command is never shared: five reads of the values are five requests.
    await Promise.all(Array.from({ length: TABS }, () => fetch(`${gw.url}/machines/printer/status/values`)));
    expect(stub.seen.filter((s) => s.url === '/status/values').length).toBe(TABS);
  });

  it('xTool: five tabs opening at once read each part of the identity once', async () => {
    const stub = await slowStub();
    const gw = await gatewayFor(cleanups, [machine('laser', 'xtool', stub.url)], { families });
    const statuses = await openTabs(gw.url, 'laser', XTOOL_OPEN);
    expect(statuses).toEqual(statuses.map(() => 200));
    for (const p of XTOOL_OPEN) expect(stub.seen.filter((s) => s.url === p).length, p).toBe(1);
  });

  it('a simulated Prunt and xTool are shared the same way', async () => {
    const gw = await gatewayFor(
      cleanups,
      [machine('sim-p', 'prunt', null), machine('sim-x', 'xtool', null)],
      {
        families,
      },
    );
    await openTabs(gw.url, 'sim-p', PRUNT_OPEN);
    await openTabs(gw.url, 'sim-x', XTOOL_OPEN);
    expect(gw.gw.upstreamStats('sim-p')?.upstreamRequests).toBe(PRUNT_OPEN.length);
    expect(gw.gw.upstreamStats('sim-x')?.upstreamRequests).toBe(XTOOL_OPEN.length);
  });
});

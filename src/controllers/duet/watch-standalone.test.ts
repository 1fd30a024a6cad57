import { afterEach, describe, expect, it } from 'vitest';
import { consoleFetch, startGateway, tempDir } from '../../../gateway/test-util';
import type { FamilyDescriptor } from '../../fleet/contract';
import type { Simulator } from '../../fleet/sim';
import { duetFamily } from './family';
import { duetSharing, duetWatch } from './sharing';
import { RrfSimulator, WEB_PAGE } from './sim/standalone';

/**
 * The console server's watch of a Duet nobody looks at, through the real gateway. The machines
 * file names no `api` (the normal case): the watch's first read opens the gateway's session,
 * whose probe finds a standalone board, and the watch reads `rr_model` from then on. A board the
 * watch cannot read (a standalone board forced to DSF: its web page for a model) is shown as "not
 * read by the server", never as nothing.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

interface Listed {
  id: string;
  watch?: { state: string; alarm: string | null; unread?: string | null };
}

async function gateway(api: 'dsf' | undefined) {
  let sim: RrfSimulator | null = null;
  const family: FamilyDescriptor = {
    ...duetFamily,
    gateway: {
      ...duetFamily.gateway,
      sharing: { ...duetSharing, watch: { ...duetWatch, everyMs: 150 } },
    },
    createSimulator: (o): Simulator => (sim = new RrfSimulator({ ...o, password: null, tickMs: 100 })),
  };
  const t = tempDir();
  cleanups.push(t.cleanup);
  const gw = await startGateway({
    machines: {
      // A machines file (not the built-in demo: no demo job), the board's API not in it.
      file: `${t.dir}/machines.json`,
      machines: [
        {
          id: 'rw',
          name: 'Duet 2',
          kind: 'duet',
          simulated: true,
          url: null,
          wsUrl: null,
          secrets: {},
          ...(api ? { api } : {}),
        },
      ],
    },
    families: { duet: family },
    dataDir: t.dir,
    env: {},
    watch: true,
  });
  cleanups.push(gw.close);
  const listed = async (): Promise<Listed | undefined> => {
    const r = await consoleFetch(`${gw.url}/api/machines`);
    const body = (await r.json()) as { machines: Listed[] };
    return body.machines.find((m) => m.id === 'rw');
  };
  const alarms = async (): Promise<Array<{ machine: string; text: string }>> => {
    const r = await consoleFetch(`${gw.url}/api/alarms`);
    return ((await r.json()) as { alarms: Array<{ machine: string; text: string }> }).alarms;
  };
  return {
    gw,
    listed,
    alarms,
    sim: (): RrfSimulator => {
      if (!sim) throw new Error('no simulator yet');
      return sim;
    },
  };
}

/** Waits (every 30 ms) until the gateway's answers say `pred`, failing after `ms`. */
async function untilAsync(pred: () => Promise<boolean>, ms = 15_000): Promise<void> {
  const end = Date.now() + ms;
  while (!(await pred())) {
    if (Date.now() > end) throw new Error('condition not met in time');
    await new Promise((r) => setTimeout(r, 30));
  }
}

describe('the server’s watch of a Duet whose API the console found by itself', () => {
  it('a standalone board found by the probe is read by rr_model (no page open): its state on the fleet’s first screen, a heater fault in the alarm centre', async () => {
    const g = await gateway(undefined);
    let m: Listed | undefined;
    await untilAsync(async () => {
      m = await g.listed();
      return m?.watch?.state === 'idle';
    });
    // At most the first read went to a DSF path (it opened the session that found the board).
    const dsfReads = () => g.sim().requests.filter((r) => r.includes('/machine/')).length;
    expect(dsfReads()).toBeLessThanOrEqual(1);
    expect(g.sim().requests).toContain('GET /rr_model');
    g.sim()
      .printer.controls()
      .find((c) => c.id === 'heater-fault')
      ?.run();
    await untilAsync(async () => {
      m = await g.listed();
      return /heater fault/i.test(m?.watch?.alarm ?? '');
    });
    await untilAsync(async () =>
      (await g.alarms()).some((a) => a.machine === 'rw' && /heater/i.test(a.text)),
    );
    // Still no DSF path asked after the first read, however many polls went by.
    expect(dsfReads()).toBeLessThanOrEqual(1);
  });

  it('a board the watch cannot read (a standalone board set to "dsf": its web page for a model) is "not read by the server", never nothing', async () => {
    const g = await gateway('dsf');
    let m: Listed | undefined;
    await untilAsync(async () => {
      m = await g.listed();
      return m?.watch?.state === 'unread';
    });
    expect(m?.watch?.unread).toMatch(/not JSON/);
    expect(m?.watch?.alarm).toBeNull();
    // The board did answer with its web page (200, HTML), as a real one does.
    const r = await g.sim().fetch(new Request('http://x/machine/model'), '/machine/model');
    expect([r.status, r.headers.get('content-type'), await r.text()]).toEqual([200, 'text/html', WEB_PAGE]);
  });
});

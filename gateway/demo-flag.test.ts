import { afterEach, describe, expect, it } from 'vitest';
import { families } from '../src/controllers/families';
import { demoFleet, type MachineEntry } from './machines';
import { startGateway, tempDir, type Running, consoleFetch } from './test-util';

const open: Array<{ close(): Promise<void> | void }> = [];
afterEach(async () => {
  for (const o of open.splice(0)) await o.close();
});

async function machinesAnswer(file: string | null, machines: MachineEntry[]): Promise<unknown> {
  const t = tempDir();
  open.push({ close: () => t.cleanup() });
  const gw: Running = await startGateway({ machines: { file, machines }, families, dataDir: t.dir, env: {} });
  open.push(gw);
  return (await consoleFetch(`${gw.url}/api/machines`)).json();
}

describe('GET /api/machines demo flag', () => {
  it('is true for the built-in demo fleet, so the console starts demo jobs', async () => {
    const body = await machinesAnswer(null, demoFleet());
    expect(body).toMatchObject({ demo: true });
    expect((body as { machines: unknown[] }).machines).toHaveLength(6);
  });

  it('is false for a machines file, even one with only simulated machines', async () => {
    expect(await machinesAnswer('/etc/shopdeck/machines.json', demoFleet())).toMatchObject({ demo: false });
  });
});

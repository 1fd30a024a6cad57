import { describe, expect, it } from 'vitest';
import { loadController, MACHINE_KINDS } from '../../controllers';
import { createRuntime } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { families } from '../../controllers/families';
import { JOB_CONTROL_ROLE, KIOSK_FAMILIES } from './per-family';

describe('the job control row of each family', () => {
  it('names commands the family declares, for the role the row shows before the code loads', async () => {
    let checked = 0;
    for (const kind of MACHINE_KINDS) {
      const family = KIOSK_FAMILIES[kind];
      if (!family) continue;
      const mod = await loadController(kind);
      // Made, never started: nothing is sent anywhere.
      const rt = createRuntime(
        { id: `row-${kind}`, name: kind, kind, simulated: true },
        (ctx) => mod.createSession(ctx),
        { visibility: alwaysVisible },
      );
      const ids = [family.pause, family.resume, family.stop, family.estop].filter(
        (id): id is string => id !== undefined,
      );
      for (const id of ids) {
        const cmd = rt.session?.commands[id];
        expect(cmd, `${kind}: ${id}`).toBeDefined();
        expect(cmd?.role, `${kind}: ${id}`).toBe(JOB_CONTROL_ROLE);
        checked++;
      }
    }
    expect(checked).toBeGreaterThanOrEqual(12);
  });

  it('are the job commands each family declares (its declaration’s jobs), and every declared one is a command', async () => {
    for (const kind of MACHINE_KINDS) {
      const jobs = families[kind]?.jobs;
      const row = KIOSK_FAMILIES[kind];
      expect(
        row ? { pause: row.pause, resume: row.resume, stop: row.stop, estop: row.estop } : undefined,
        kind,
      ).toEqual(
        jobs ? { pause: jobs.pause, resume: jobs.resume, stop: jobs.stop, estop: jobs.estop } : undefined,
      );
      if (!jobs) continue;
      const mod = await loadController(kind);
      const rt = createRuntime(
        { id: `jobs-${kind}`, name: kind, kind, simulated: true },
        (ctx) => mod.createSession(ctx),
        {
          visibility: alwaysVisible,
        },
      );
      for (const id of Object.values(jobs)) expect(rt.session?.commands[id], `${kind}: ${id}`).toBeDefined();
    }
  });
});

import { describe, expect, it } from 'vitest';
import { emptySnapshot } from '../../fleet/types';
import { touchcutAccess } from './access';
import { activityOf, alarmsOf, snapshotPatch } from './normalize';
import { statusSchema } from './wire';

const status = (o: Record<string, unknown>) => statusSchema.parse(o);

describe('touchcut status → snapshot', () => {
  it('maps known state words and keeps unknown ones visible', () => {
    expect(activityOf(status({ machineState: 'Idle', stateName: 'Idle' })).activity).toBe('idle');
    expect(activityOf(status({ machineState: 'Running', stateName: 'Cutting' }))).toEqual({
      activity: 'running',
      label: 'Cutting',
    });
    expect(activityOf(status({ machineState: 'Paused' })).activity).toBe('paused');
    expect(activityOf(status({ machineState: 'E-Stop' })).activity).toBe('error');
    expect(activityOf(status({ machineState: 'Quantum' }))).toEqual({
      activity: 'unknown',
      label: 'unknown (raw "Quantum")',
    });
  });

  it('turns msgStatus into alarms that keep their start time', () => {
    const first = alarmsOf([{ key: 'TorchCollision', msg: 'Torch collision detected' }], [], 1000);
    expect(first[0]).toMatchObject({ id: 'msg:TorchCollision', severity: 'critical', since: 1000 });
    const again = alarmsOf(
      [
        { key: 'TorchCollision', msg: 'Torch collision detected' },
        { key: 'Info', msg: 'Program loaded' },
      ],
      first,
      5000,
    );
    expect(again.map((a) => [a.id, a.since, a.severity])).toEqual([
      ['msg:TorchCollision', 1000, 'critical'],
      ['msg:Info', 5000, 'info'],
    ]);
  });

  it('a critical message while running makes the activity "alarm"; no program means no job', () => {
    const { patch } = snapshotPatch(
      status({
        machineState: 'Running',
        programName: 'A.nc',
        programProgress: 40,
        msgStatus: [{ key: 'ArcLost', msg: 'Arc lost' }],
      }),
      emptySnapshot('x'),
      { name: null, startedAt: null, lastProgress: null },
      0,
    );
    expect(patch.activity).toBe('alarm');
    expect(patch.job).toMatchObject({ name: 'A.nc', progress: 0.4 });
    const idle = snapshotPatch(
      status({ machineState: 'Idle', programName: 'No Active Program' }),
      emptySnapshot('x'),
      { name: null, startedAt: null, lastProgress: null },
      0,
    );
    expect(idle.patch.job).toBeNull();
  });
});

describe('touchcut access policy', () => {
  const req = (method: string, path: string) => ({ method, path, query: new URLSearchParams() });
  it('reads are viewer reads, the shared login and the password change are audited operator commands', () => {
    for (const p of ['status', 'stats', 'monitor', 'programs', 'unloader', 'screenshot', 'machine-info']) {
      expect(touchcutAccess(req('GET', `/rest/v1/${p}`))).toMatchObject({ role: 'viewer', command: false });
    }
    expect(touchcutAccess(req('POST', '/rest/v1/auth'))).toMatchObject({ role: 'operator', command: true });
    expect(touchcutAccess(req('POST', '/rest/v1/auth/change-password/'))).toMatchObject({
      role: 'operator',
      command: true,
    });
    expect(touchcutAccess(req('POST', '/rest/v1/status'))).toMatchObject({
      role: 'supervisor',
      command: true,
    });
    expect(touchcutAccess(req('DELETE', '/rest/v1/programs'))).toMatchObject({ role: 'supervisor' });
    expect(touchcutAccess(req('PUT', '/anything'))).toMatchObject({ role: 'supervisor' });
  });
});

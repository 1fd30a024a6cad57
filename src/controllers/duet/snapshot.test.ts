import { describe, expect, it } from 'vitest';
import { fixtureJson } from './fixtures.test-util';
import { applyPatch } from './patch';
import { activityOf, jobSummary, snapshotOf, STATUS_WORDS, temperatures } from './snapshot';
import { MACHINE_STATUSES, machineStatus, objectModelSchema } from './wire';

const gemini = () => objectModelSchema.parse(fixtureJson('object-model/model_geminiv2.json'));

describe('snapshot mapping', () => {
  it('has words and an activity for all 14 statuses, and survives unknown ones', () => {
    expect(MACHINE_STATUSES).toHaveLength(14);
    for (const s of MACHINE_STATUSES) expect(STATUS_WORDS[s], s).toBeTruthy();
    expect(activityOf('processing')).toBe('running');
    expect(activityOf('pausing')).toBe('paused');
    expect(activityOf('cancelling')).toBe('stopping');
    expect(activityOf('halted')).toBe('error');
    expect(activityOf('off')).toBe('idle');
    expect(activityOf(machineStatus.parse('teleporting'))).toBe('unknown');
  });

  it('maps the real idle model: no job, sensorless heaters read as unknown, identity', () => {
    const m = gemini();
    const s = snapshotOf(m, () => 1);
    expect(s.activity).toBe('idle');
    expect(s.job).toBeNull();
    expect(s.identity).toBe('fly_geminiv2.0 · RRF 3.5.0-rc.2+101 · DSF 3.5.0-rc.2');
    expect(temperatures(m)).toEqual([
      { name: 'Bed', current: null, target: null },
      { name: 'Tool 0', current: null, target: null },
    ]);
    expect(s.positions).toEqual({ X: 0, Y: 0, Z: 0 });
    expect(s.alarms).toEqual([]);
  });

  it('a printing model: progress from filePosition / size, remaining from timesLeft, alarms', () => {
    const raw = applyPatch(
      fixtureJson('object-model/model_geminiv2.json'),
      fixtureJson('patches/dsf-python/test_job_1__job-file-with-thumbnail.json'),
    ).model;
    const printing = applyPatch(raw, {
      state: { status: 'processing', messageBox: { mode: 2, seq: 5, title: 'Check', message: 'ok?' } },
      job: { filePosition: 297097, duration: 120, timesLeft: { file: 300, filament: 310, slicer: 400 } },
      heat: { heaters: [{ state: 'active', active: 60, current: 59.5 }, { state: 'fault' }] },
    }).model;
    const m = objectModelSchema.parse(printing);
    const job = jobSummary(m);
    expect(job?.name).toBe('Veil_Token.gcode');
    expect(job?.progress).toBeCloseTo(0.5, 3);
    expect(job?.remaining).toBe(300);
    const s = snapshotOf(m, () => 42);
    // The percentage is the job line's alone (one record, one rounding: issue 33).
    expect(s.activityLabel).toBe('Printing Veil_Token.gcode');
    expect(s.temperatures?.[0]).toEqual({ name: 'Bed', current: 59.5, target: 60 });
    expect(s.alarms?.map((a) => a.id)).toEqual(['heater-1-fault', 'messagebox-5']);
    expect(s.alarms?.[0]?.clears).toMatch(/M562 P1/);
  });
});

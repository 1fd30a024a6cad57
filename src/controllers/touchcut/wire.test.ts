import { describe, expect, it } from 'vitest';
import {
  MANUAL_AUTH_SUCCESS_TEXT,
  MANUAL_ERROR_BODIES,
  MANUAL_MONITOR_TEXT,
  MANUAL_STATUS_TEXT,
} from './sim/data/manual';
import {
  authResponseSchema,
  errorBodySchema,
  monitorSchema,
  progressFraction,
  statsSchema,
  statusSchema,
  unitLabel,
} from './wire';

/** The manual's status example with its extraction damage (`\)`) repaired to the obvious `\")`. */
function repairedStatus(): unknown {
  expect(() => JSON.parse(MANUAL_STATUS_TEXT) as unknown).toThrow();
  return JSON.parse(MANUAL_STATUS_TEXT.replace('(0.394\\)', '(0.394\\")')) as unknown;
}

describe('touchcut wire: manual examples', () => {
  it('parses the manual status example', () => {
    const s = statusSchema.parse(repairedStatus());
    expect(s.machineState).toBe('Idle');
    expect(s.toolName).toBe('Laser Pointer');
    expect(s.material).toBe('MS-10.00 mm (0.394")');
    expect(s.activeCarriages).toEqual([1]);
    expect(s.actualPos?.vec).toEqual([0, 0, 0]);
    expect(s.msgStatus).toEqual([]);
    expect(s.heightControlAuto).toBe(true);
    expect(s.units).toBe('metric');
  });

  it('parses the manual monitor example, where io is an empty array', () => {
    const m = monitorSchema.parse(JSON.parse(MANUAL_MONITOR_TEXT));
    expect(m.axes.map((a) => a.name)).toEqual(['axisLong', 'axisShort']);
    expect(m.axes[1]?.index).toBe('10');
    expect(m.axes[0]?.torqueLimit).toBe(150);
    expect(m.io).toEqual({ din: [], dout: [], ain: [], aout: [] });
    expect(m.axes[0]?.io.din).toEqual([]);
  });

  it('parses every error body printed in the manual', () => {
    for (const [name, text] of Object.entries(MANUAL_ERROR_BODIES)) {
      const r = errorBodySchema.safeParse(JSON.parse(text));
      expect(r.success, name).toBe(true);
      expect(r.data?.code).toMatch(/^\d+$/);
    }
  });

  it('parses the auth success body, where success is the string "true"', () => {
    const a = authResponseSchema.parse(JSON.parse(MANUAL_AUTH_SUCCESS_TEXT));
    expect(a.success).toBe(true);
    expect(a.token).toBe('<JWT>');
    expect(authResponseSchema.safeParse({ success: 'true' }).success).toBe(false);
  });
});

describe('touchcut wire: leniency', () => {
  it('coerces numbers and booleans sent as strings and keeps unknown keys and states', () => {
    const s = statusSchema.parse({
      feedOverride: '95.5',
      toolOn: 'true',
      isHomed: 0,
      machineState: 'Warp Drive',
      newThing: { a: 1 },
      msgStatus: ['Plain text message', { key: 'k', msg: 'm' }],
    });
    expect(s.feedOverride).toBe(95.5);
    expect(s.toolOn).toBe(true);
    expect(s.isHomed).toBe(false);
    expect(s.machineState).toBe('Warp Drive');
    expect((s as Record<string, unknown>).newThing).toEqual({ a: 1 });
    expect(s.msgStatus[0]).toEqual({ key: 'Plain text message', msg: 'Plain text message' });
  });

  it('fails with a path when a value is really wrong', () => {
    const r = statusSchema.safeParse({ actualPos: { vec: ['x'] } });
    expect(r.success).toBe(false);
    expect(r.error?.issues[0]?.path).toEqual(['actualPos', 'vec', 0]);
  });

  it('accepts monitor io as an object of groups and as an array of group objects', () => {
    const din = [{ name: 'E-Stop', address: 'IO 1', value: 'true' }];
    const ain = [{ name: 'Arc voltage', address: 'AI 1', scale: '1', value: '121.5', unitType: 'V' }];
    const asObject = monitorSchema.parse({ io: { din, ain } });
    const asArray = monitorSchema.parse({ io: [{ din }, { ain }] });
    expect(asObject.io).toEqual(asArray.io);
    expect(asArray.io.din[0]?.value).toBe(true);
    expect(asArray.io.ain[0]?.value).toBe(121.5);
  });

  it('keeps a uint64 error code that does not fit a double as text', () => {
    const m = monitorSchema.parse({ axes: [{ name: 'a', errorCode: '18446744073709551615' }] });
    expect(m.axes[0]?.errorCode).toBe('18446744073709551615');
  });

  it('reads programProgress as a percentage', () => {
    expect(progressFraction(50)).toBe(0.5);
    expect(progressFraction(150)).toBe(1);
    expect(progressFraction(undefined)).toBeNull();
  });

  it('labels units from the answer', () => {
    expect(unitLabel('utLength', 'metric')).toBe('mm');
    expect(unitLabel('utFeed', 'imperial')).toBe('in/min');
    expect(unitLabel('utMystery', 'metric')).toBe('utMystery');
  });
});

describe('touchcut wire: stats', () => {
  const session = (user: string) => ({
    user,
    startTime: '2026-01-05T08:00:00',
    activeTime: '3600',
    toolTotals: [],
  });

  it('finds sessions, programs and errors at the top level and in unnamed wrappers', () => {
    const s = statsSchema.parse({
      machine: [{ tool: 1, name: 'Plasma', time: 10, carriages: [{ carriage: 1, time: 10 }] }],
      sessions: [session('top')],
      days: [
        {
          date: '2026-01-05',
          sessions: [session('a')],
          programs: [{ startTime: 't', name: 'P1' }],
          errors: [],
        },
        {
          date: '2026-01-06',
          sessions: [session('b')],
          errors: [{ errorTime: 't', error: 'Torch collision' }],
        },
      ],
      period: { sessions: [session('c')] },
      consumables: [{ consID: 'E1', pierces: '12' }],
      units: 'metric',
    });
    expect(s.sessions.map((x) => x.user)).toEqual(['top', 'a', 'b', 'c']);
    expect(s.sessions[0]?.activeTime).toBe(3600);
    expect(s.programs).toEqual([{ startTime: 't', name: 'P1' }]);
    expect(s.errors.map((e) => e.error)).toEqual(['Torch collision']);
    expect(s.consumables[0]?.pierces).toBe(12);
    expect(s.machine[0]?.carriages[0]?.carriage).toBe(1);
  });

  it('reports the path of a broken nested session', () => {
    const r = statsSchema.safeParse({ days: [{ sessions: [{ user: 'a', activeTime: 'lots' }] }] });
    expect(r.success).toBe(false);
    expect(r.error?.issues[0]?.path).toEqual(['days', 0, 'sessions', 0, 'activeTime']);
  });
});

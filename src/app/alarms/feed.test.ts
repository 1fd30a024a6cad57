import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { authStore } from '../../fleet/auth';
import { criticalAlarms } from '../AlarmBanner';
import { filterAlarms, NO_FILTERS } from './AlarmsPage';
import { alarmFeed, onNewAlarm, refreshAlarms, stopAlarmFeedForTests, type AlarmRecord } from './feed';

function rec(id: string, over: Partial<AlarmRecord> = {}): AlarmRecord {
  return {
    id,
    machine: 'laser-1',
    machineName: 'Laser 1',
    family: 'xtool',
    key: `k${id}`,
    severity: 'warning',
    text: `alarm ${id}`,
    blocking: false,
    since: 1000 + Number(id),
    clearedAt: null,
    ackBy: null,
    ackAt: null,
    ...over,
  };
}

let answers: Array<{ status: number; body: unknown }> = [];
const asked: string[] = [];

beforeEach(() => {
  answers = [];
  asked.length = 0;
  authStore.setState({ mode: 'open', user: null });
  vi.stubGlobal(
    'fetch',
    vi.fn((url: string) => {
      asked.push(url);
      const a = answers.shift() ?? { status: 500, body: { error: 'no answer prepared' } };
      return Promise.resolve(new Response(JSON.stringify(a.body), { status: a.status }));
    }),
  );
});
afterEach(() => {
  stopAlarmFeedForTests();
  vi.unstubAllGlobals();
});

describe('the alarm feed', () => {
  it('keeps the list, asks with `since` afterwards, and tells of records new to this page', async () => {
    const seen: string[] = [];
    const off = onNewAlarm((r) => seen.push(r.id));
    answers.push({ status: 200, body: { version: 3, alarms: [rec('1')] } });
    await refreshAlarms();
    expect(alarmFeed.getState().records?.map((r) => r.id)).toEqual(['1']);
    // The first list is what the page found, not news.
    expect(seen).toEqual([]);
    answers.push({ status: 200, body: { version: 3, unchanged: true } });
    await refreshAlarms();
    expect(asked[1]).toMatch(/since=3/);
    expect(alarmFeed.getState().records?.map((r) => r.id)).toEqual(['1']);
    answers.push({
      status: 200,
      body: { version: 4, alarms: [rec('2', { severity: 'critical' }), rec('1')] },
    });
    await refreshAlarms();
    expect(seen).toEqual(['2']);
    off();
  });

  it('a malformed or refused answer is an error in words; the last good list stays', async () => {
    answers.push({ status: 200, body: { version: 1, alarms: [rec('1')] } });
    await refreshAlarms();
    answers.push({ status: 200, body: { version: 2, alarms: [{ ...rec('2'), severity: '<img src=x>' }] } });
    await refreshAlarms();
    expect(alarmFeed.getState().error).toMatch(/malformed/);
    expect(alarmFeed.getState().records?.map((r) => r.id)).toEqual(['1']);
    answers.push({ status: 503, body: { error: 'down' } });
    await refreshAlarms();
    expect(alarmFeed.getState().error).toMatch(/HTTP 503/);
    expect(alarmFeed.getState().records?.map((r) => r.id)).toEqual(['1']);
  });

  it('asks nothing while nobody is signed in', async () => {
    authStore.setState({ mode: 'secured', user: null });
    await refreshAlarms();
    expect(asked).toEqual([]);
  });
});

describe('critical alarms on every page', () => {
  const local = [
    { machineId: 'laser-1', machineName: 'Laser 1', key: 'xtool-flame', message: 'FLAME', since: 5 },
  ];

  it('shows the list’s unacknowledged critical alarms, blocking or not', () => {
    const out = criticalAlarms(
      [
        rec('1', { severity: 'critical', key: 'xtool-flame', blocking: true }),
        rec('2', { severity: 'critical', machine: 'cnc', key: 'g2core-panic' }),
        rec('3', { severity: 'critical', ackAt: 9, ackBy: 'olga' }),
        rec('4', { severity: 'warning' }),
      ],
      [],
    );
    expect(out.map((b) => [b.recordId, b.blocking])).toEqual([
      ['1', true],
      ['2', false],
    ]);
  });

  it('adds what only this page has seen, until the list has it unacknowledged', () => {
    expect(criticalAlarms(null, local).map((b) => [b.key, b.recordId, b.blocking])).toEqual([
      ['xtool-flame', null, true],
    ]);
    expect(criticalAlarms([], local)).toHaveLength(1);
    // An acknowledged record of the key may be an earlier flame: this page's own stays shown.
    const acked = rec('7', { severity: 'critical', key: 'xtool-flame', ackAt: 9, ackBy: 'olga' });
    expect(criticalAlarms([acked], local).map((b) => [b.key, b.recordId])).toEqual([['xtool-flame', null]]);
    const open = rec('8', { severity: 'critical', key: 'xtool-flame', blocking: true });
    expect(criticalAlarms([open], local).map((b) => b.recordId)).toEqual(['8']);
  });
});

describe('the alarm centre’s filters', () => {
  const list = [
    rec('1', { severity: 'info', since: 10 }),
    rec('2', { severity: 'critical', since: 5, clearedAt: 8 }),
    rec('3', { severity: 'critical', since: 7, machine: 'cnc', family: 'g2core' }),
    rec('4', { severity: 'warning', since: 20, ackAt: 21, ackBy: 'olga' }),
  ];
  it('sorts most severe first, active before cleared, then newest', () => {
    expect(filterAlarms(list, NO_FILTERS).map((r) => r.id)).toEqual(['3', '2', '4', '1']);
  });
  it('filters by machine, family, severity and state', () => {
    const ids = (f: Partial<typeof NO_FILTERS>) =>
      filterAlarms(list, { ...NO_FILTERS, ...f }).map((r) => r.id);
    expect(ids({ machine: 'cnc' })).toEqual(['3']);
    expect(ids({ family: 'xtool' })).toEqual(['2', '4', '1']);
    expect(ids({ severity: 'critical' })).toEqual(['3', '2']);
    expect(ids({ state: 'active' })).toEqual(['3', '4', '1']);
    expect(ids({ state: 'unacknowledged' })).toEqual(['3', '2', '1']);
  });
});

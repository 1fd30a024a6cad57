import { describe, expect, it } from 'vitest';
import { earlierFromAnswer, earlierNote, withEarlier, type Point } from './server-temperatures';

/** The chart's earlier readings (the server's last minutes) and how the live points follow them. */

const answer = (now: number, samples: Array<Array<number | null>>) => ({
  machine: 'd1',
  now,
  windowMs: 600_000,
  everyMs: 1000,
  sensors: [
    { key: '0', name: 'Bed' },
    { key: '1', name: 'Tool 0' },
  ],
  samples,
});

describe('earlier readings from the server', () => {
  it('moves the server’s times into the page’s clock (the clocks differ), per sensor, skipping nulls', () => {
    // The server's clock is 90 s ahead of the tablet's.
    const serverNow = 1_000_090_000;
    const pageNow = 1_000_000_000;
    const e = earlierFromAnswer(
      answer(serverNow, [
        [serverNow - 3000, 60, null],
        [serverNow - 2000, 61, 200],
        [serverNow - 1000, 62, 201],
      ]),
      pageNow,
    );
    expect(e.state).toBe('ok');
    if (e.state !== 'ok') return;
    expect(e.byKey.get('0')?.points).toEqual([
      [pageNow - 3000, 60],
      [pageNow - 2000, 61],
      [pageNow - 1000, 62],
    ]);
    expect(e.byKey.get('1')).toEqual({
      name: 'Tool 0',
      points: [
        [pageNow - 2000, 200],
        [pageNow - 1000, 201],
      ],
    });
  });

  it('says "none" for an empty answer and "error" for a malformed one, never an empty chart that looks read', () => {
    expect(earlierFromAnswer(answer(5, []), 5)).toEqual({ state: 'none' });
    expect(earlierFromAnswer({ samples: 'lots' }, 5).state).toBe('error');
    expect(earlierFromAnswer(answer(5, [[1, Number.POSITIVE_INFINITY as number]]), 5).state).toBe('error');
    expect(earlierNote({ state: 'none' })).toMatch(/no earlier readings on the server/i);
    expect(earlierNote({ state: 'error', message: 'HTTP 503' })).toMatch(/could not be read.*HTTP 503/);
    expect(earlierNote({ state: 'loading' })).toMatch(/reading/i);
  });
});

describe('withEarlier: the server’s minutes, then the live points', () => {
  const earlier: Point[] = [
    [1000, 20],
    [2000, 21],
    [3000, 22],
    [4000, 23],
    [5000, 24],
  ];

  it('keeps every earlier point older than the first live one, then all live ones: no duplicate, no gap', () => {
    const live: Point[] = [
      [4200, 23.4],
      [5200, 24.2],
    ];
    const merged = withEarlier(earlier, live);
    expect(merged).toEqual([[1000, 20], [2000, 21], [3000, 22], ...live]);
    // Strictly increasing times: no moment twice.
    for (let i = 1; i < merged.length; i++) expect(merged[i]![0]).toBeGreaterThan(merged[i - 1]![0]);
    // No gap: the earlier part ends within a sample period and a half before the live part.
    const lastEarlier = merged[merged.length - live.length - 1]![0];
    expect(live[0]![0] - lastEarlier).toBeLessThanOrEqual(1500);
  });

  it('a point within half a sample of the first live one is the same moment: dropped', () => {
    expect(withEarlier(earlier, [[5300, 24.1]]).map((p) => p[0])).toEqual([1000, 2000, 3000, 4000, 5300]);
  });

  it('no live point yet: the earlier ones alone; no earlier ones: the live ones alone', () => {
    expect(withEarlier(earlier, [])).toBe(earlier);
    const live: Point[] = [[9000, 1]];
    expect(withEarlier(undefined, live)).toBe(live);
    expect(withEarlier([], live)).toBe(live);
    // Live points all older than the server's (a page open for long): the live ones alone.
    expect(withEarlier(earlier, [[500, 19]])).toEqual([[500, 19]]);
  });
});

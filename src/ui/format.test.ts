process.env.TZ = 'Europe/Berlin';
import { afterAll, afterEach, beforeAll, describe, expect, it, vi } from 'vitest';
import {
  formatAge,
  formatBytes,
  formatDateTime,
  formatDuration,
  formatNumber,
  formatPercent,
  formatTime,
} from './format';

// The browser's own language and time zone: an English (UK) browser in Berlin.
vi.stubGlobal('navigator', { language: 'en-GB', languages: ['en-GB', 'en'] });
afterAll(() => {
  vi.unstubAllGlobals();
});

/** 2024-03-10 00:30:00 in Berlin (CET, UTC+1) is still 2024-03-09 in UTC. */
const HALF_PAST_MIDNIGHT_BERLIN = Date.UTC(2024, 2, 9, 23, 30, 0);

describe('issue 12 (5): dates in the browser time zone', () => {
  it('formatDateTime at 00:30 in Berlin shows that day, not the UTC day before', () => {
    expect(formatDateTime(HALF_PAST_MIDNIGHT_BERLIN)).toBe('10/03/2024, 00:30:00');
  });

  it('formatTime agrees with formatDateTime', () => {
    expect(formatTime(HALF_PAST_MIDNIGHT_BERLIN)).toBe('00:30:00');
  });

  it('writes the date in the order of the browser language', () => {
    vi.stubGlobal('navigator', { language: 'de-DE', languages: ['de-DE', 'de'] });
    try {
      expect(formatDateTime(HALF_PAST_MIDNIGHT_BERLIN)).toBe('10.03.2024, 00:30:00');
    } finally {
      vi.stubGlobal('navigator', { language: 'en-GB', languages: ['en-GB', 'en'] });
    }
  });
});

describe('issue 12 (5): one locale policy', () => {
  // The module is new with the fix; imported here so the tests above fail on the defect itself.
  let setLocalePolicy: typeof import('./locale').setLocalePolicy;
  beforeAll(async () => {
    ({ setLocalePolicy } = await import('./locale'));
  });
  afterEach(() => setLocalePolicy({}));

  it('an explicit time zone wins over the process one', () => {
    setLocalePolicy({ timeZone: 'America/New_York' });
    expect(formatDateTime(HALF_PAST_MIDNIGHT_BERLIN)).toBe('09/03/2024, 18:30:00');
    setLocalePolicy({ timeZone: 'UTC' });
    expect(formatDateTime(HALF_PAST_MIDNIGHT_BERLIN)).toBe('09/03/2024, 23:30:00');
  });

  it('a locale setting wins over the browser language', () => {
    setLocalePolicy({ locale: 'de-DE' });
    expect(formatNumber(1234.56, 1, 'mm')).toBe('1.234,6 mm');
    expect(formatPercent(0.425, 1)).toBe('42,5\u00a0%');
    expect(formatBytes(1536)).toBe('1,5 KiB');
    expect(formatDateTime(HALF_PAST_MIDNIGHT_BERLIN)).toBe('10.03.2024, 00:30:00');
  });

  it('numbers, durations and ages follow the browser language', () => {
    expect(formatNumber(1234.56, 1, 'mm')).toBe('1,234.6 mm');
    expect(formatPercent(0.42)).toBe('42%');
    expect(formatDuration(3725)).toBe('1 h 02 min');
    expect(formatDuration(1200)).toBe('20 min 00 s');
    expect(formatAge(1_000, 5_000)).toBe('4 sec ago');
    expect(formatAge(5_000, 5_000)).toBe('0 sec ago');
    expect(formatAge(0, 7_300_000)).toBe('2 hr ago');
    expect(formatAge(null, 5_000)).toBe('never');
  });

  it('an unknown or malformed locale falls back to the next one, never throws', () => {
    setLocalePolicy({ locale: 'not a locale!' });
    expect(() => formatNumber(1.5)).not.toThrow();
    vi.stubGlobal('navigator', { language: '', languages: ['', 'x-bogus-@@', 'fr-FR'] });
    try {
      setLocalePolicy({});
      expect(formatNumber(1234.5, 1)).toBe('1\u202f234,5');
    } finally {
      vi.stubGlobal('navigator', { language: 'en-GB', languages: ['en-GB', 'en'] });
    }
  });
});

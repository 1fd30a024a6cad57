// @vitest-environment happy-dom
import { cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it } from 'vitest';
import type { HistoryInfo } from './api';
import { HistorySettings } from './HistorySettings';

afterEach(cleanup);

const info: HistoryInfo = {
  sizeBytes: 4096,
  schemaVersion: 1,
  oldest: { jobAt: null, stateAt: null, touchcutDay: '2027-04-01' },
  counts: { jobs: 3, states: 4, touchcutDays: 12 },
  shifts: [],
  retention: { jobsDays: 365, statesDays: 90 },
};

describe('the history settings', () => {
  it('name the imported daily statistics as the family that has them names them (its manifest)', () => {
    render(<HistorySettings info={info} onSaved={() => undefined} />);
    const kv = screen.getByTestId('history-info');
    const terms = [...kv.querySelectorAll('dt')].map((d) => d.textContent);
    expect(terms).toContain('TouchCut days');
    const row = [...kv.querySelectorAll('dt')].find((d) => d.textContent === 'TouchCut days');
    expect(row?.nextElementSibling?.textContent).toBe('12 (oldest 2027-04-01)');
  });
});

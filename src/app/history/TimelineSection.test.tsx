// @vitest-environment happy-dom
import { act, cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { TimelineSection } from './TimelineSection';

function json(body: unknown, status = 200): Response {
  return new Response(JSON.stringify(body), { status, headers: { 'Content-Type': 'application/json' } });
}

const from = new Date(2026, 2, 10).getTime();
const to = from + 86_400_000;
const good = {
  from,
  to,
  truncated: false,
  machines: [
    {
      machine: 'x1',
      machineName: 'Laser bay',
      family: 'xtool',
      intervals: [
        { state: 'running', alarm: null, from: from + 3_600_000, to: from + 7_200_000, open: false },
      ],
    },
  ],
};

afterEach(() => {
  cleanup();
  vi.unstubAllGlobals();
});

describe('TimelineSection', () => {
  it('draws a strip per machine; a malformed answer is an error on screen and the last good strip stays', async () => {
    const answers = [json(good), json({ ...good, machines: [{ machine: 'x1' }] })];
    const fetchMock = vi.fn((_url: string) => Promise.resolve(answers.shift() ?? json({}, 500)));
    vi.stubGlobal('fetch', fetchMock);
    const view = render(<TimelineSection range={{ from, to }} tick={0} now={to} />);
    const strip = await screen.findByTestId('history-strip-x1');
    expect(strip.querySelectorAll('rect[data-state="running"]')).toHaveLength(1);
    expect(strip.querySelector('svg')?.getAttribute('aria-label')).toMatch(
      /^Laser bay: Not recorded 23 h 00 min, Running 1 h 00 min/,
    );
    expect(fetchMock.mock.calls[0]?.[0]).toBe(`/api/history/states?from=${from}&to=${to}`);

    await act(async () => {
      view.rerender(<TimelineSection range={{ from, to }} tick={1} now={to} />);
      await Promise.resolve();
    });
    expect(await screen.findByText('The timeline answer is malformed.', { exact: false })).toBeTruthy();
    expect(screen.getByText(/What is shown is from the last answer/)).toBeTruthy();
    expect(
      screen.getByTestId('history-strip-x1').querySelectorAll('rect[data-state="running"]'),
    ).toHaveLength(1);
    expect(fetchMock).toHaveBeenCalledTimes(2);
  });
});

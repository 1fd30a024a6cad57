// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen, within } from '@testing-library/react';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { fleetStore } from '../../fleet/fleet';
import { AuditPage, detailAfter, PAGE_SIZE } from './AuditPage';

function json(body: unknown, status = 200): Response {
  return new Response(JSON.stringify(body), { status, headers: { 'Content-Type': 'application/json' } });
}

const entries = [
  {
    time: '2026-01-05T10:02:00.000Z',
    type: 'refused',
    result: 'refused',
    user: 'vera',
    machine: 'laser-1',
    method: 'GET',
    path: '/cnc/data?action=stop',
    label: 'stop the job',
    role: 'operator',
    source: 'gateway',
  },
  {
    time: '2026-01-05T10:01:00.000Z',
    type: 'command',
    result: 'ok',
    user: 'sam',
    onBehalfOf: 'otto',
    machine: 'laser-1',
    method: 'GET',
    path: '/cnc/data?action=pause',
    commandId: 'xtool.pause',
    label: 'pause the job',
    status: 200,
    source: 'gateway',
  },
  { time: '2026-01-05T10:00:00.000Z', type: 'login', result: 'ok', user: 'otto', source: 'gateway' },
];

async function flush() {
  await act(async () => {
    await Promise.resolve();
  });
}

describe('AuditPage', () => {
  let fetchMock: ReturnType<typeof vi.fn<typeof fetch>>;
  beforeEach(() => {
    fleetStore.setState({
      status: 'ready',
      error: null,
      machines: [{ id: 'laser-1', name: 'Laser 1', kind: 'xtool', simulated: false }],
    });
    fetchMock = vi.fn<typeof fetch>((url) =>
      Promise.resolve(
        json({
          entries: String(url).includes('result=refused') ? entries.slice(0, 1) : entries,
          total: String(url).includes('result=refused') ? 1 : 120,
        }),
      ),
    );
    vi.stubGlobal('fetch', fetchMock);
  });
  afterEach(() => {
    cleanup();
    vi.unstubAllGlobals();
  });

  it('shows who did what where, newest first, with the result', async () => {
    render(<AuditPage />);
    await flush();
    expect(String(fetchMock.mock.calls[0]![0])).toBe(`/api/audit?offset=0&limit=${PAGE_SIZE}`);
    const rows = within(screen.getByTestId('audit-table')).getAllByRole('row').slice(1);
    expect(rows).toHaveLength(3);
    expect(rows[0]!.textContent).toMatch(/vera.*Laser 1.*stop the job.*refused.*needs operator/);
    expect(rows[1]!.textContent).toMatch(
      /sam on otto’s tablet.*pause the job \(xtool\.pause\).*ok.*HTTP 200/,
    );
    expect(rows[2]!.textContent).toContain('Login');
  });

  it('filters, pages and exports CSV with the same filters', async () => {
    render(<AuditPage />);
    await flush();
    expect(screen.getByText('Page 1 of 3')).toBeTruthy();
    fireEvent.click(screen.getByRole('button', { name: 'Older' }));
    await flush();
    expect(String(fetchMock.mock.calls.at(-1)![0])).toBe(`/api/audit?offset=${PAGE_SIZE}&limit=${PAGE_SIZE}`);
    fireEvent.change(screen.getByLabelText('Result'), { target: { value: 'refused' } });
    fireEvent.change(screen.getByLabelText('Machine'), { target: { value: 'laser-1' } });
    fireEvent.change(screen.getByLabelText('User'), { target: { value: 'vera' } });
    fireEvent.click(screen.getByRole('button', { name: 'Apply filters' }));
    await flush();
    expect(String(fetchMock.mock.calls.at(-1)![0])).toBe(
      `/api/audit?machine=laser-1&user=vera&result=refused&offset=0&limit=${PAGE_SIZE}`,
    );
    expect(within(screen.getByTestId('audit-table')).getAllByRole('row')).toHaveLength(2);
    expect(screen.getByRole('link', { name: 'Export CSV' }).getAttribute('href')).toBe(
      '/api/audit.csv?machine=laser-1&user=vera&result=refused',
    );
  });

  it('explains a refusal for non-supervisors', async () => {
    fetchMock.mockImplementation(() =>
      Promise.resolve(json({ error: 'the audit log is for supervisors', needs: 'supervisor' }, 403)),
    );
    render(<AuditPage />);
    await flush();
    expect(screen.getByText('Supervisors only')).toBeTruthy();
    expect(screen.getByText('the audit log is for supervisors')).toBeTruthy();
  });
});

describe("the audit page's words", () => {
  it("never repeats the label's word in the detail (entries written before the rewording too)", () => {
    expect(detailAfter('job started', 'started: a.nc')).toBe('a.nc');
    expect(detailAfter('job started', 'a.nc')).toBe('a.nc');
    expect(detailAfter('User added', 'added as operator, by root (command line)')).toBe(
      'as operator, by root (command line)',
    );
    expect(detailAfter('alarm cleared', 'cleared: flame')).toBe('flame');
    expect(detailAfter('job started', 'startedXY.nc')).toBe('startedXY.nc');
  });
});

import { useCallback, useEffect, useState } from 'react';
import { apiOrigin, CONSOLE_HEADERS } from '../fleet/origin';
import { simPanelSchema, type SimControlView, type SimGroup, type SimPanel } from '../fleet/sim-panel';
import { Button, EmptyState, Notice, Panel } from '../ui';

/**
 * The Simulator tab of a simulated machine (supervisors): stand-ins for the physical world, fault
 * injection, a restart. The simulator runs in the console's server, not in this page: every tab
 * sees the same simulated world, and every change goes through the gateway's access control and
 * audit log (`GET`/`POST /api/sim/<id>`, gateway/sim-api.ts). The controls are the gateway's
 * answer, described as data (src/fleet/sim-panel.ts).
 */

/** Test ids the browser tests use, by fault control. */
const FAULT_TEST_IDS: Record<string, string> = {
  drop: 'fault-drop',
  http5xx: 'fault-5xx',
  malformed: 'fault-malformed',
  latencyMs: 'fault-latency',
  closeSockets: 'fault-close-sockets',
};

function testIdOf(c: SimControlView): string {
  if (c.group === 'world') return `sim-control-${c.id}`;
  if (c.group === 'faults') return FAULT_TEST_IDS[c.id] ?? `fault-${c.id}`;
  return `sim-${c.id}`;
}

async function simRequest(id: string, set?: { group: SimGroup; id: string; value?: boolean | number }) {
  const r = await fetch(`${apiOrigin()}/api/sim/${encodeURIComponent(id)}`, {
    method: set ? 'POST' : 'GET',
    credentials: 'same-origin',
    headers: set ? { 'Content-Type': 'application/json', ...CONSOLE_HEADERS } : CONSOLE_HEADERS,
    body: set ? JSON.stringify(set) : undefined,
  });
  const body: unknown = await r.json().catch(() => null);
  if (!r.ok) {
    const error = (body as { error?: unknown } | null)?.error;
    throw new Error(typeof error === 'string' ? error : `the gateway answered HTTP ${r.status}`);
  }
  const parsed = simPanelSchema.safeParse(body);
  if (!parsed.success) throw new Error('the gateway’s answer about the simulator is malformed');
  return parsed.data;
}

export function SimulatorPanel({ id }: { id: string }) {
  const [panel, setPanel] = useState<SimPanel | null>(null);
  const [error, setError] = useState<string | null>(null);
  const [busy, setBusy] = useState<string | null>(null);

  useEffect(() => {
    let live = true;
    simRequest(id).then(
      (p) => {
        if (live) setPanel(p);
      },
      (e: unknown) => {
        if (live) setError(e instanceof Error ? e.message : String(e));
      },
    );
    return () => {
      live = false;
    };
  }, [id]);

  const set = useCallback(
    (c: SimControlView, value?: boolean | number) => {
      const key = `${c.group}.${c.id}`;
      setError(null);
      setBusy(key);
      // Shown at once; the gateway's answer (the simulator's real state) replaces it.
      if (value !== undefined)
        setPanel(
          (p) =>
            p && {
              ...p,
              controls: p.controls.map((x) =>
                x.group === c.group && x.id === c.id && x.type !== 'action'
                  ? ({ ...x, value } as SimControlView)
                  : x,
              ),
            },
        );
      // Not aborted when the tab closes: the physical world changes whether or not anyone watches.
      simRequest(id, { group: c.group, id: c.id, value })
        .then(
          (p) => setPanel(p),
          (e: unknown) => {
            setError(e instanceof Error ? e.message : String(e));
            return simRequest(id).then(setPanel, () => undefined);
          },
        )
        .finally(() => setBusy((b) => (b === key ? null : b)));
    },
    [id],
  );

  if (!panel) {
    return error ? (
      <Notice tone="bad" title="The simulator cannot be reached" testId="sim-error">
        {error}
      </Notice>
    ) : (
      <EmptyState>Asking the console’s server for this simulator…</EmptyState>
    );
  }
  const group = (g: SimGroup) => panel.controls.filter((c) => c.group === g);
  const world = group('world');
  const control = (c: SimControlView) => {
    const testId = testIdOf(c);
    const key = `${c.group}.${c.id}`;
    switch (c.type) {
      case 'action':
        return (
          <Button key={key} busy={busy === key} onClick={() => set(c)} data-testid={testId}>
            {c.label}
          </Button>
        );
      case 'toggle':
        return (
          <label key={key} className="check">
            <input
              type="checkbox"
              checked={c.value}
              onChange={(e) => set(c, e.target.checked)}
              data-testid={testId}
            />{' '}
            {c.label}
          </label>
        );
      case 'choice':
        return (
          <label key={key} className="check">
            {c.label}{' '}
            <select
              className="ui-input"
              value={c.value}
              onChange={(e) => set(c, Number(e.target.value))}
              data-testid={testId}
            >
              {c.choices.map((v) => (
                <option key={v} value={v}>
                  {v}
                  {c.unit ? ` ${c.unit}` : ''}
                </option>
              ))}
            </select>
          </label>
        );
    }
  };
  return (
    <div className="ui-grid" data-testid="sim-panel">
      <Notice tone="info" title="Simulated">
        This simulator runs in the console’s server: what you change here changes the simulated machine for
        every tab and every user, and is written to the audit log.
      </Notice>
      {error && (
        <Notice tone="bad" title="The simulator refused" testId="sim-error">
          {error}
        </Notice>
      )}
      <Panel title="Physical world (simulated)">
        {world.length === 0 && <EmptyState>No controls for this simulator.</EmptyState>}
        <div className="ui-row">{world.map(control)}</div>
      </Panel>
      <Panel title="Fault injection">
        <div className="ui-row">{group('faults').map(control)}</div>
      </Panel>
      <Panel title="Simulator">
        <div className="ui-row">{group('simulator').map(control)}</div>
      </Panel>
    </div>
  );
}

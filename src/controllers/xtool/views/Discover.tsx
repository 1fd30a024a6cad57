import { useState } from 'react';
import { describeError } from '../../../fleet/errors';
import { Button, DataTable, EmptyState, Notice, Panel } from '../../../ui';
import { discoverLasers, machineEntry } from '../discover';
import type { DiscoveryResponse } from '../wire';

/** "Find lasers" (/xtool/discover): the gateway broadcasts, this page lists who answered. */
export function Discover() {
  const [result, setResult] = useState<DiscoveryResponse | null>(null);
  const [error, setError] = useState<string | null>(null);
  const [busy, setBusy] = useState(false);

  const search = () => {
    setBusy(true);
    setError(null);
    discoverLasers()
      .then(setResult)
      .catch((e: unknown) => setError(describeError(e)))
      .finally(() => setBusy(false));
  };

  const taken = new Set<string>();
  const rows = (result?.replies ?? []).map((r) => {
    const entry = machineEntry(r, taken);
    taken.add(entry.id);
    return { r, entry };
  });

  return (
    <div style={{ display: 'grid', gap: 14 }} data-testid="xtool-discover">
      <Panel
        title="Find xTool lasers"
        level={1}
        actions={
          <Button
            variant="primary"
            onClick={search}
            busy={busy}
            disabled={busy}
            data-testid="xtool-discover-search"
          >
            {busy ? 'Searching (2 s)…' : 'Search the network'}
          </Button>
        }
      >
        <p className="ui-muted">
          The console's server broadcasts a discovery request to UDP port 20000 and listens two seconds for
          answers (UDP 20000, TCP 20001). Lasers behind a firewall that blocks TCP 20001 answer about 20 s
          late and may be missed: search again. The answer does not say the model: D-series (D1, D1 Pro, D1
          Pro 2.0) lasers work here; other xTool models are recognized and shown as unsupported when added.
        </p>
        {result?.broadcast && <p className="ui-muted">Broadcast to {result.broadcast}.</p>}
        {result?.warnings?.map((w) => (
          <Notice key={w} tone="warn" title="The search had a problem">
            {w}
          </Notice>
        ))}
        {error && (
          <Notice tone="bad" title="Search failed">
            {error}
          </Notice>
        )}
      </Panel>
      {result && (
        <Panel title={`${result.replies.length} answer${result.replies.length === 1 ? '' : 's'}`}>
          {rows.length === 0 ? (
            <EmptyState>No laser answered.</EmptyState>
          ) : (
            <>
              <DataTable
                testId="xtool-discover-table"
                rows={rows}
                rowKey={(x, i) => `${x.r.ip}-${i}`}
                columns={[
                  {
                    key: 'name',
                    label: 'Name',
                    render: (x) => x.r.name || <span className="ui-muted">(no name)</span>,
                  },
                  { key: 'ip', label: 'Address', render: (x) => <span className="mono">{x.r.ip}</span> },
                  { key: 'version', label: 'Firmware', render: (x) => x.r.version || '—' },
                  { key: 'via', label: 'Answered by', render: (x) => x.r.via },
                ]}
              />
              <h3>Add to the machines file</h3>
              <p className="ui-muted">
                Copy these entries into the <span className="mono">machines</span> list of the machines file
                and restart the console.
              </p>
              <pre className="mono" data-testid="xtool-discover-entries" style={{ overflowX: 'auto' }}>
                {rows.map((x) => JSON.stringify(x.entry)).join(',\n')}
              </pre>
            </>
          )}
        </Panel>
      )}
    </div>
  );
}

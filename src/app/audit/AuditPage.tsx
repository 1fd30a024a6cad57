import { useCallback, useEffect, useMemo, useState } from 'react';
import { z } from 'zod/mini';
import { useStore } from 'zustand';
import { fleetStore } from '../../fleet/fleet';
import { CONSOLE_HEADERS } from '../../fleet/origin';
import {
  Badge,
  Button,
  DataTable,
  Field,
  Notice,
  Panel,
  formatDateTime,
  type Column,
  type Tone,
} from '../../ui';
import { auditQuery, type AuditFilters } from '../auth/api';
import { usePageTitle } from '../router';
import './audit.css';

/**
 * `/audit`: the gateway's audit log (commands with who/when/what/result, logins, failed
 * logins, refused requests, role changes), newest first, with filters and a CSV export.
 */

const EntrySchema = z.looseObject({
  time: z.string(),
  type: z.string(),
  result: z.string(),
  user: z.string(),
  source: z.optional(z.string()),
  machine: z.optional(z.string()),
  method: z.optional(z.string()),
  path: z.optional(z.string()),
  commandId: z.optional(z.string()),
  /** The page's own name for a command (X-Shopdeck-Command): a label, not what the gateway classified. */
  clientCommand: z.optional(z.string()),
  label: z.optional(z.string()),
  status: z.optional(z.number()),
  detail: z.optional(z.string()),
  error: z.optional(z.string()),
  role: z.optional(z.string()),
  address: z.optional(z.string()),
  onBehalfOf: z.optional(z.string()),
});
const AnswerSchema = z.object({ entries: z.array(EntrySchema), total: z.number() });
export type AuditRow = z.infer<typeof EntrySchema>;

export const PAGE_SIZE = 50;

const TYPE_WORDS: Record<string, string> = {
  command: 'Command',
  refused: 'Refused',
  login: 'Login',
  'login-failed': 'Failed login',
  logout: 'Logout',
  'session-expired': 'Session expired',
  elevate: 'PIN unlock',
  'elevate-failed': 'Failed PIN unlock',
  'elevate-end': 'Locked again',
  'user-added': 'User added',
  'user-removed': 'User removed',
  'role-change': 'Role change',
  'password-change': 'Password change',
  machine: 'Machine',
  'alarm-ack': 'Alarm acknowledged',
  settings: 'Settings',
};

const RESULT_TONE: Record<string, Tone> = { ok: 'ok', error: 'bad', refused: 'warn', failed: 'bad' };

/**
 * An entry's detail without a repeat of the label's last word: entries written before the
 * details were reworded said "job started" + "started: a.nc" and "User added" + "added as …".
 */
export function detailAfter(label: string, detail: string): string {
  const last = (label.trim().split(/\s+/).pop() ?? '').toLowerCase();
  const d = detail.trim();
  if (last && d.toLowerCase().startsWith(last) && /^[\s:,]|^$/.test(d.slice(last.length)))
    return d.slice(last.length).replace(/^[\s:,]+/, '');
  return d;
}

function what(e: AuditRow): string {
  const label = e.label ?? TYPE_WORDS[e.type] ?? e.type;
  const parts = [label];
  if (e.commandId) parts.push(`(${e.commandId})`);
  if (e.clientCommand && e.clientCommand !== e.commandId) parts.push(`(page: ${e.clientCommand})`);
  if (
    e.type === 'role-change' ||
    e.type === 'user-added' ||
    e.type === 'user-removed' ||
    e.type === 'password-change' ||
    e.type === 'machine' ||
    e.type === 'alarm-ack' ||
    e.type === 'settings'
  ) {
    const d = detailAfter(label, e.detail ?? '');
    if (d) parts.push(`(${d})`);
  }
  return parts.filter(Boolean).join(' ');
}

function outcome(e: AuditRow): string {
  const bits: string[] = [];
  if (e.status !== undefined) bits.push(`HTTP ${e.status}`);
  if (e.error) bits.push(e.error);
  else if (e.detail && e.type === 'command') bits.push(e.detail);
  if (e.type === 'refused' && e.role) bits.push(`needs ${e.role}`);
  return bits.join(' · ');
}

/** The table's columns; `names`: machine id → the name the machines file gives it. */
function columns(names: ReadonlyMap<string, string>): Column<AuditRow>[] {
  return [
    {
      key: 'time',
      label: 'Time',
      render: (e) => <span className="audit-time">{formatDateTime(Date.parse(e.time))}</span>,
    },
    {
      key: 'user',
      label: 'Who',
      render: (e) => (
        <span>
          {e.user}
          {e.onBehalfOf && <span className="ui-muted"> on {e.onBehalfOf}’s tablet</span>}
          {e.source === 'client' && <span className="ui-muted"> (simulated, from the browser)</span>}
          {e.source === 'cli' && <span className="ui-muted"> (server console)</span>}
        </span>
      ),
    },
    {
      key: 'machine',
      label: 'Machine',
      // The machine's name; the id only for a machine no longer in the machines file.
      render: (e) =>
        e.machine === undefined ? '—' : <span title={e.machine}>{names.get(e.machine) ?? e.machine}</span>,
    },
    { key: 'what', label: 'What', render: (e) => what(e) },
    {
      key: 'request',
      label: 'Request',
      render: (e) =>
        e.method || e.path ? (
          <code className="audit-path">{`${e.method ?? ''} ${e.path ?? ''}`.trim()}</code>
        ) : (
          '—'
        ),
    },
    {
      key: 'result',
      label: 'Result',
      render: (e) => (
        <span className="audit-result">
          <Badge tone={RESULT_TONE[e.result] ?? 'muted'}>{e.result}</Badge>{' '}
          <span className="ui-muted">{outcome(e)}</span>
        </span>
      ),
    },
  ];
}

type Load =
  | { state: 'loading' }
  | { state: 'ok'; entries: AuditRow[]; total: number }
  | { state: 'error'; message: string; status: number };

export function AuditPage() {
  usePageTitle('Audit log');
  const machines = useStore(fleetStore, (s) => s.machines);
  const cols = useMemo(() => columns(new Map(machines.map((m) => [m.id, m.name]))), [machines]);
  const [draft, setDraft] = useState<AuditFilters>({});
  const [filters, setFilters] = useState<AuditFilters>({});
  const [offset, setOffset] = useState(0);
  const [load, setLoad] = useState<Load>({ state: 'loading' });
  const [tick, setTick] = useState(0);

  const refresh = useCallback(() => setTick((t) => t + 1), []);

  useEffect(() => {
    const ctl = new AbortController();
    setLoad((l) => (l.state === 'ok' ? l : { state: 'loading' }));
    fetch(`/api/audit${auditQuery(filters, { offset, limit: PAGE_SIZE })}`, {
      credentials: 'same-origin',
      headers: CONSOLE_HEADERS,
      signal: ctl.signal,
    })
      .then(async (r) => {
        if (!r.ok) {
          let message = `The gateway answered HTTP ${r.status}.`;
          try {
            const b = (await r.json()) as { error?: unknown };
            if (typeof b.error === 'string') message = b.error;
          } catch {
            // keep the status text
          }
          setLoad({ state: 'error', message, status: r.status });
          return;
        }
        const parsed = AnswerSchema.safeParse(await r.json());
        if (!parsed.success)
          setLoad({ state: 'error', message: 'The audit log answer is malformed.', status: 0 });
        else setLoad({ state: 'ok', entries: parsed.data.entries, total: parsed.data.total });
      })
      .catch((e: unknown) => {
        if (ctl.signal.aborted) return;
        setLoad({ state: 'error', message: e instanceof Error ? e.message : String(e), status: 0 });
      });
    return () => ctl.abort();
  }, [filters, offset, tick]);

  const apply = () => {
    setOffset(0);
    setFilters({ ...draft });
  };
  const clear = () => {
    setDraft({});
    setOffset(0);
    setFilters({});
  };
  const set = (k: keyof AuditFilters) => (v: string) => setDraft((d) => ({ ...d, [k]: v || undefined }));

  const total = load.state === 'ok' ? load.total : 0;
  const pageCount = Math.max(1, Math.ceil(total / PAGE_SIZE));
  const page = Math.floor(offset / PAGE_SIZE) + 1;

  return (
    <div className="audit-page" data-testid="audit-page">
      <Panel
        title="Audit log"
        level={1}
        actions={
          <>
            <Button onClick={refresh}>Refresh</Button>
            <a
              className="ui-button secondary audit-csv"
              href={`/api/audit.csv${auditQuery(filters)}`}
              download="shopdeck-audit.csv"
            >
              Export CSV
            </a>
          </>
        }
      >
        <form
          className="audit-filters"
          onSubmit={(e) => {
            e.preventDefault();
            apply();
          }}
        >
          <Field label="Machine">
            {(id) => (
              <select
                id={id}
                className="ui-input"
                value={draft.machine ?? ''}
                onChange={(e) => set('machine')(e.target.value)}
              >
                <option value="">All machines</option>
                {machines.map((m) => (
                  <option key={m.id} value={m.id}>
                    {m.name} ({m.id})
                  </option>
                ))}
              </select>
            )}
          </Field>
          <Field label="User">
            {(id) => (
              <input
                id={id}
                className="ui-input"
                value={draft.user ?? ''}
                autoCapitalize="off"
                placeholder="any"
                onChange={(e) => set('user')(e.target.value)}
              />
            )}
          </Field>
          <Field label="Result">
            {(id) => (
              <select
                id={id}
                className="ui-input"
                value={draft.result ?? ''}
                onChange={(e) => set('result')(e.target.value)}
              >
                <option value="">Any result</option>
                <option value="ok">ok</option>
                <option value="error">error (the controller refused or failed)</option>
                <option value="refused">refused (by the gateway)</option>
                <option value="failed">failed (login or PIN)</option>
              </select>
            )}
          </Field>
          <Field label="From">
            {(id) => (
              <input
                id={id}
                className="ui-input"
                type="datetime-local"
                value={draft.from ?? ''}
                onChange={(e) => set('from')(e.target.value)}
              />
            )}
          </Field>
          <Field label="To">
            {(id) => (
              <input
                id={id}
                className="ui-input"
                type="datetime-local"
                value={draft.to ?? ''}
                onChange={(e) => set('to')(e.target.value)}
              />
            )}
          </Field>
          <div className="ui-row audit-filter-actions">
            <Button type="submit" variant="primary">
              Apply filters
            </Button>
            <Button onClick={clear}>Clear</Button>
          </div>
        </form>

        {load.state === 'error' && (
          <Notice
            tone={load.status === 403 ? 'warn' : 'bad'}
            title={load.status === 403 ? 'Supervisors only' : 'Cannot load the audit log'}
          >
            {load.message}
          </Notice>
        )}
        {load.state === 'loading' && <p className="ui-muted">Loading…</p>}
        {load.state === 'ok' && (
          <>
            <DataTable
              columns={cols}
              rows={load.entries}
              rowKey={(e, i) => `${e.time}-${i + offset}`}
              empty="Nothing in the audit log matches these filters."
              caption={`${total} ${total === 1 ? 'entry' : 'entries'}, newest first`}
              testId="audit-table"
            />
            {total > PAGE_SIZE && (
              <nav className="ui-row audit-paging" aria-label="Pages">
                <Button disabled={offset === 0} onClick={() => setOffset(Math.max(0, offset - PAGE_SIZE))}>
                  Newer
                </Button>
                <span>
                  Page {page} of {pageCount}
                </span>
                <Button disabled={offset + PAGE_SIZE >= total} onClick={() => setOffset(offset + PAGE_SIZE)}>
                  Older
                </Button>
              </nav>
            )}
          </>
        )}
      </Panel>
    </div>
  );
}

import { useEffect, useMemo, useState } from 'react';
import { z } from 'zod/mini';
import { useStore } from 'zustand';
import { familyLabel } from '../../controllers';
import { fleetStore } from '../../fleet/fleet';
import { CONSOLE_HEADERS } from '../../fleet/origin';
import { useCan } from '../../fleet/react';
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
import { setAlarmSound, useAlarmSoundSetting } from '../AlarmBanner';
import { Link, usePageTitle } from '../router';
import { acknowledgeAlarm, alarmFeed, type AlarmRecord } from './feed';
import './alarms.css';

/**
 * `/alarms`: the alarm centre. Every alarm and message of every machine the person may see, as
 * the gateway recorded them (also while no page was open), newest and most severe first, with
 * filters; acknowledgement (operators); this tablet's sound and notifications; and, for
 * supervisors, where alarms are sent on (the webhook of the server settings).
 */

type StateFilter = 'active' | 'unacknowledged' | 'all';

export interface AlarmFilters {
  machine: string;
  family: string;
  severity: '' | AlarmRecord['severity'];
  state: StateFilter;
}

export const NO_FILTERS: AlarmFilters = { machine: '', family: '', severity: '', state: 'all' };

const SEVERITY_TONE: Record<AlarmRecord['severity'], Tone> = {
  critical: 'bad',
  warning: 'warn',
  info: 'info',
};
const SEVERITY_RANK: Record<AlarmRecord['severity'], number> = { critical: 2, warning: 1, info: 0 };

/** The records the filters keep, most severe first, then active before cleared, then newest. */
export function filterAlarms(records: readonly AlarmRecord[], f: AlarmFilters): AlarmRecord[] {
  return records
    .filter(
      (r) =>
        (!f.machine || r.machine === f.machine) &&
        (!f.family || r.family === f.family) &&
        (!f.severity || r.severity === f.severity) &&
        (f.state === 'all' ||
          (f.state === 'active' && r.clearedAt === null) ||
          (f.state === 'unacknowledged' && r.ackAt === null)),
    )
    .sort(
      (a, b) =>
        SEVERITY_RANK[b.severity] - SEVERITY_RANK[a.severity] ||
        Number(a.clearedAt !== null) - Number(b.clearedAt !== null) ||
        b.since - a.since,
    );
}

function AckCell({ r, canAck }: { r: AlarmRecord; canAck: boolean }) {
  const [busy, setBusy] = useState(false);
  const [error, setError] = useState<string | null>(null);
  if (r.ackAt !== null)
    return (
      <span data-testid={`acked-${r.id}`}>
        {r.ackBy ?? 'someone'}, {formatDateTime(r.ackAt)}
      </span>
    );
  if (!canAck) return <span className="ui-muted">not yet</span>;
  return (
    <span>
      <Button
        small
        variant={r.severity === 'critical' ? 'danger' : 'secondary'}
        busy={busy}
        disabled={busy}
        data-testid={`ack-alarm-${r.id}`}
        onClick={() => {
          setBusy(true);
          void acknowledgeAlarm({ id: r.id }).then((e) => {
            setBusy(false);
            setError(e);
          });
        }}
      >
        Acknowledge
      </Button>
      {error && (
        <span role="alert" className="alarm-error">
          {' '}
          {error}
        </span>
      )}
    </span>
  );
}

function columns(canAck: boolean): Column<AlarmRecord>[] {
  return [
    {
      key: 'severity',
      label: 'Severity',
      render: (r) => <Badge tone={SEVERITY_TONE[r.severity]}>{r.severity}</Badge>,
    },
    {
      key: 'machine',
      label: 'Machine',
      render: (r) => <Link to={`/m/${encodeURIComponent(r.machine)}`}>{r.machineName}</Link>,
    },
    { key: 'text', label: 'Alarm', render: (r) => <span className="alarm-text">{r.text}</span> },
    { key: 'since', label: 'Since', render: (r) => formatDateTime(r.since) },
    {
      key: 'state',
      label: 'Now',
      render: (r) =>
        r.clearedAt === null ? (
          <Badge tone="bad">active</Badge>
        ) : (
          <span className="ui-muted">cleared {formatDateTime(r.clearedAt)}</span>
        ),
    },
    { key: 'ack', label: 'Acknowledged', render: (r) => <AckCell r={r} canAck={canAck} /> },
  ];
}

function ThisTablet() {
  const sound = useAlarmSoundSetting();
  const [permission, setPermission] = useState<NotificationPermission | 'unsupported'>(() =>
    typeof Notification === 'undefined' ? 'unsupported' : Notification.permission,
  );
  return (
    <Panel title="On this tablet" testId="alarm-tablet">
      <div className="ui-row alarm-tablet">
        <Button onClick={() => setAlarmSound(!sound)} aria-pressed={!sound} data-testid="alarm-sound-setting">
          {sound ? 'Sound on: mute critical alarms here' : 'Sound muted here: turn it on'}
        </Button>
        {permission === 'unsupported' ? (
          <span className="ui-muted">This browser shows no notifications.</span>
        ) : permission === 'granted' ? (
          <span>Notifications are on for new alarms.</span>
        ) : permission === 'denied' ? (
          <span className="ui-muted">Notifications are blocked in this browser’s site settings.</span>
        ) : (
          <Button
            onClick={() => void Notification.requestPermission().then((p) => setPermission(p))}
            data-testid="alarm-notify"
          >
            Notify me of new alarms
          </Button>
        )}
      </div>
      {!window.isSecureContext && (
        <p className="ui-muted small">
          Notifications need HTTPS (or this computer itself): see the README, “HTTPS”.
        </p>
      )}
    </Panel>
  );
}

const settingsSchema = z.object({
  alarmWebhook: z.object({ set: z.boolean(), shown: z.nullable(z.string()), fromEnvironment: z.boolean() }),
  webhook: z.object({ delivered: z.number(), failed: z.number(), dropped: z.number(), waiting: z.number() }),
});
type SettingsView = z.infer<typeof settingsSchema>;

async function call(method: string, path: string, body?: unknown): Promise<{ ok: boolean; json: unknown }> {
  const r = await fetch(path, {
    method,
    credentials: 'same-origin',
    headers: { ...CONSOLE_HEADERS, ...(body === undefined ? {} : { 'Content-Type': 'application/json' }) },
    ...(body === undefined ? {} : { body: JSON.stringify(body) }),
  });
  let json: unknown = null;
  try {
    json = await r.json();
  } catch {
    json = null;
  }
  return { ok: r.ok, json };
}

function errorOf(json: unknown, fallback: string): string {
  const e = z.object({ error: z.string() }).safeParse(json);
  return e.success ? e.data.error : fallback;
}

/** Supervisors: where alarms are sent on (a webhook URL; its secret part is never shown back). */
function SendOn() {
  const [view, setView] = useState<SettingsView | null>(null);
  const [url, setUrl] = useState('');
  const [message, setMessage] = useState<{ tone: Tone; text: string } | null>(null);
  const [busy, setBusy] = useState(false);
  const load = () =>
    void call('GET', '/api/settings')
      .then(({ ok, json }) => {
        const v = settingsSchema.safeParse(json);
        if (ok && v.success) setView(v.data);
        else setMessage({ tone: 'bad', text: errorOf(json, 'The settings could not be read.') });
      })
      .catch(() => setMessage({ tone: 'bad', text: 'The settings could not be read.' }));
  useEffect(load, []);
  const run = (f: () => Promise<void>) => {
    setBusy(true);
    setMessage(null);
    void f()
      .catch((e: unknown) => setMessage({ tone: 'bad', text: e instanceof Error ? e.message : String(e) }))
      .finally(() => setBusy(false));
  };
  const save = (value: string | null) =>
    run(async () => {
      const { ok, json } = await call('PUT', '/api/settings', { alarmWebhook: value });
      if (!ok) {
        setMessage({ tone: 'bad', text: errorOf(json, 'Not saved.') });
        return;
      }
      setUrl('');
      setMessage({
        tone: 'ok',
        text: value ? 'Saved: new alarms are sent there.' : 'Removed: alarms are not sent on.',
      });
      load();
    });
  const test = () =>
    run(async () => {
      const { json } = await call('POST', '/api/settings/test-webhook');
      // Only "delivered" or "failed": why is in the server's log (the answer tells nothing of the
      // network behind the console).
      const r = z.object({ ok: z.boolean(), result: z.enum(['delivered', 'failed']) }).safeParse(json);
      if (!r.success) setMessage({ tone: 'bad', text: errorOf(json, 'The test could not be sent.') });
      else if (r.data.ok) setMessage({ tone: 'ok', text: 'Delivered: the receiver took the test.' });
      else
        setMessage({
          tone: 'bad',
          text: 'Failed: the test was not delivered (the server’s log says why; addresses of this computer, link-local addresses and the machines are refused unless the server’s settings file allows them).',
        });
    });
  const w = view?.alarmWebhook;
  return (
    <Panel title="Send alarms on" testId="alarm-webhook">
      <p className="small">
        Every alarm, its clearing and its acknowledgement are posted as JSON to this address (a chat or paging
        service’s “incoming webhook”), retried for about 12 minutes while it is down.
      </p>
      {w && (
        <p data-testid="webhook-now">
          {w.set ? (
            <>
              Now sent to <code>{w.shown}</code>
              {w.fromEnvironment && ' (set by the server: SHOPDECK_ALARM_WEBHOOK)'}.
            </>
          ) : (
            'Not sent on: no address is set.'
          )}{' '}
          {view.webhook.delivered > 0 || view.webhook.failed > 0
            ? `Since the console started: ${view.webhook.delivered} delivered, ${view.webhook.failed} failed, ${view.webhook.waiting} waiting.`
            : ''}
        </p>
      )}
      {w && !w.fromEnvironment && (
        <form
          className="ui-row alarm-webhook-form"
          onSubmit={(e) => {
            e.preventDefault();
            if (url.trim()) save(url.trim());
          }}
        >
          <Field
            label="Webhook URL"
            hint="https://… (the address is kept on the console; only its host is shown again)"
          >
            {(id) => (
              <input
                id={id}
                className="ui-input"
                type="url"
                value={url}
                onChange={(e) => setUrl(e.target.value)}
                placeholder="https://hooks.example.com/…"
                autoComplete="off"
                data-testid="webhook-url"
              />
            )}
          </Field>
          <Button type="submit" variant="primary" disabled={busy || !url.trim()}>
            Save
          </Button>
          {w.set && (
            <Button disabled={busy} onClick={() => save(null)}>
              Remove
            </Button>
          )}
        </form>
      )}
      {w?.set && (
        <Button disabled={busy} onClick={test} data-testid="webhook-test">
          Send a test
        </Button>
      )}
      {message && <Notice tone={message.tone}>{message.text}</Notice>}
    </Panel>
  );
}

/** One filter of the list: a labelled select over fixed values. */
function FilterSelect<V extends string>(props: {
  label: string;
  value: V;
  onChange: (v: V) => void;
  options: ReadonlyArray<readonly [V, string]>;
  testId: string;
}) {
  return (
    <Field label={props.label}>
      {(id) => (
        <select
          id={id}
          className="ui-input"
          value={props.value}
          onChange={(e) => {
            const v = props.options.find(([x]) => x === e.target.value);
            if (v) props.onChange(v[0]);
          }}
          data-testid={props.testId}
        >
          {props.options.map(([v, words]) => (
            <option key={v} value={v}>
              {words}
            </option>
          ))}
        </select>
      )}
    </Field>
  );
}

export function AlarmsPage() {
  usePageTitle('Alarms');
  const records = useStore(alarmFeed, (s) => s.records);
  const error = useStore(alarmFeed, (s) => s.error);
  const machines = useStore(fleetStore, (s) => s.machines);
  const canAck = useCan('operator');
  const isSupervisor = useCan('supervisor');
  const [filters, setFilters] = useState<AlarmFilters>(NO_FILTERS);
  const rows = useMemo(() => filterAlarms(records ?? [], filters), [records, filters]);
  const cols = useMemo(() => columns(canAck), [canAck]);
  // Machines: those of the fleet, and those only the history names (removed from the machines file).
  const machineOptions = useMemo(() => {
    const m = new Map(machines.map((x) => [x.id, x.name]));
    for (const r of records ?? []) if (!m.has(r.machine)) m.set(r.machine, r.machineName);
    return [...m.entries()].sort((a, b) => a[1].localeCompare(b[1]));
  }, [machines, records]);
  const families = useMemo(() => [...new Set((records ?? []).map((r) => r.family))].sort(), [records]);
  const set = <K extends keyof AlarmFilters>(k: K, v: AlarmFilters[K]) =>
    setFilters((f) => ({ ...f, [k]: v }));

  return (
    <div className="alarms-page" data-testid="alarms-page">
      <Panel title="Alarm centre" level={1}>
        <p className="small">
          Every alarm and message of every machine, recorded by the console whether or not a screen is open.
          An alarm clears itself when the machine clears it and stays in this list; a person acknowledges it.
        </p>
        <div className="ui-row alarm-filters" role="group" aria-label="Filters">
          <FilterSelect
            label="Machine"
            value={filters.machine}
            onChange={(v) => set('machine', v)}
            testId="alarm-filter-machine"
            options={[['', 'All machines'], ...machineOptions]}
          />
          <FilterSelect
            label="Family"
            value={filters.family}
            onChange={(v) => set('family', v)}
            testId="alarm-filter-family"
            options={[['', 'All families'], ...families.map((f): [string, string] => [f, familyLabel(f)])]}
          />
          <FilterSelect
            label="Severity"
            value={filters.severity}
            onChange={(v) => set('severity', v)}
            testId="alarm-filter-severity"
            options={[
              ['', 'All severities'],
              ['critical', 'Critical'],
              ['warning', 'Warning'],
              ['info', 'Info'],
            ]}
          />
          <FilterSelect
            label="Show"
            value={filters.state}
            onChange={(v) => set('state', v)}
            testId="alarm-filter-state"
            options={[
              ['all', 'Active and cleared'],
              ['active', 'Active only'],
              ['unacknowledged', 'Not acknowledged'],
            ]}
          />
          {filters !== NO_FILTERS && <Button onClick={() => setFilters(NO_FILTERS)}>Clear filters</Button>}
        </div>
        {error && (
          <Notice tone="bad" testId="alarm-feed-error">
            {error} {records ? 'The list below is the last one received.' : ''}
          </Notice>
        )}
        {records === null && !error ? (
          <p role="status">Loading the alarm list…</p>
        ) : (
          <DataTable
            caption="Alarms"
            columns={cols}
            rows={rows}
            rowKey={(r) => r.id}
            empty={records?.length ? 'No alarm matches these filters.' : 'No alarm recorded yet.'}
            testId="alarm-table"
          />
        )}
      </Panel>
      <ThisTablet />
      {isSupervisor && <SendOn />}
    </div>
  );
}

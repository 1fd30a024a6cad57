import { useMemo } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { DataTable, Panel, formatPercent, type CsvColumn } from '../../../ui';
import { useStats } from '../queries';
import type { TouchcutSession } from '../session';
import {
  consumableTotals,
  duration,
  hours,
  length,
  lengthUnit,
  programCounts,
  sessionsByUser,
  shiftDate,
  TIME_PARTS,
  toolTotalsOfSessions,
  totalsRows,
  type TotalsRow,
  type UserTotals,
  type ConsumableTotal,
} from '../stats';
import type { Consumable, ErrorRecord, ProgramRun } from '../wire';
import { CsvButton, num } from './common';

/** The statistics of the range read (StatsView.tsx picks it): summary cards, tables, CSV exports. */
export function StatsBody({ session }: TabProps<TouchcutSession>) {
  const { data, request, loading } = useStats(session.stats);
  const derived = useMemo(() => {
    if (!data) return null;
    const users = sessionsByUser(data.sessions);
    const tools = toolTotalsOfSessions(data.sessions);
    return {
      users,
      tools,
      cons: consumableTotals(data.consumables),
      programs: programCounts(data.programs),
      active: users.reduce((n, u) => n + u.activeTime, 0),
      productive: users.reduce((n, u) => n + u.productiveTime, 0),
      toolOn: users.reduce((n, u) => n + u.toolOnTime, 0),
      pierces: tools.reduce((n, t) => n + t.starts, 0),
      distance: tools.reduce((n, t) => n + t.distance, 0),
    };
  }, [data]);
  if (!data || !derived) return null;
  const u = data.units;
  const lu = lengthUnit(u);
  const days = data.periods.map((p) => p.date).filter((d): d is string => !!d);
  const tag = request ? `${request.startDate}_to_${request.endBeforeDate}` : 'range';
  // Only knowable when the answer names its days (the wrapper is unnamed in the manual).
  const clipped =
    !!request &&
    days.length > 0 &&
    ((days[0] ?? '') > request.startDate ||
      (days[days.length - 1] ?? '') < shiftDate(request.endBeforeDate, -1));

  const totalsCsv: CsvColumn<TotalsRow>[] = [
    { label: 'tool', value: (r) => r.tool },
    { label: 'carriage', value: (r) => r.carriage },
    { label: 'time_s', value: (r) => r.time },
    { label: `distance_${lu}`, value: (r) => r.distance },
    { label: 'starts', value: (r) => r.starts },
    { label: 'errors', value: (r) => r.errors },
    { label: 'last_reset', value: (r) => r.lastReset },
  ];
  const totalsColumns = (reset: boolean) => [
    { key: 'tool', label: 'Tool' },
    { key: 'carriage', label: 'Carriage' },
    { key: 'time', label: 'Time (h)', align: 'right' as const, render: (r: TotalsRow) => hours(r.time) },
    {
      key: 'distance',
      label: 'Distance',
      align: 'right' as const,
      render: (r: TotalsRow) => length(r.distance, u),
    },
    { key: 'starts', label: 'Starts', align: 'right' as const, render: (r: TotalsRow) => num(r.starts, 0) },
    { key: 'errors', label: 'Errors', align: 'right' as const, render: (r: TotalsRow) => num(r.errors, 0) },
    ...(reset
      ? [
          {
            key: 'lastReset',
            label: 'Last reset',
            render: (r: TotalsRow) => r.lastReset.replace('T', ' ') || '—',
          },
        ]
      : []),
  ];
  const userCsv: CsvColumn<UserTotals>[] = [
    { label: 'user', value: (r) => r.user },
    { label: 'sessions', value: (r) => r.sessions },
    { label: 'active_s', value: (r) => r.activeTime },
    { label: 'productive_s', value: (r) => r.productiveTime },
    { label: 'unproductive_s', value: (r) => r.unproductiveTime },
    { label: 'error_s', value: (r) => r.errorTime },
    { label: 'idle_s', value: (r) => r.idleTime },
    { label: 'xy_moving_s', value: (r) => r.xyMovingTime },
    { label: 'tool_on_s', value: (r) => r.toolOnTime },
  ];
  const consTotalCsv: CsvColumn<ConsumableTotal>[] = [
    { label: 'tool', value: (r) => r.toolName },
    { label: 'type', value: (r) => r.consType },
    { label: 'id', value: (r) => r.consID },
    { label: 'records', value: (r) => r.records },
    { label: 'pierces', value: (r) => r.pierces },
    { label: `distance_${lu}`, value: (r) => r.distance },
    { label: 'time_s', value: (r) => r.time },
  ];
  const consCsv: CsvColumn<Consumable>[] = [
    { label: 'date', value: (r) => r.date ?? '' },
    { label: 'tool', value: (r) => r.toolName ?? '' },
    { label: 'material', value: (r) => r.material ?? '' },
    { label: `thickness_${lu}`, value: (r) => r.thickness ?? '' },
    { label: 'process', value: (r) => r.process ?? '' },
    { label: 'type', value: (r) => r.consType ?? '' },
    { label: 'id', value: (r) => r.consID ?? '' },
    { label: 'pierces', value: (r) => r.pierces ?? '' },
    { label: `distance_${lu}`, value: (r) => r.distance ?? '' },
    { label: 'time_s', value: (r) => r.time ?? '' },
  ];
  const progCsv: CsvColumn<ProgramRun>[] = [
    { label: 'start', value: (r) => r.startTime ?? '' },
    { label: 'program', value: (r) => r.name ?? '' },
  ];
  const errCsv: CsvColumn<ErrorRecord>[] = [
    { label: 'time', value: (r) => r.errorTime ?? '' },
    { label: 'error', value: (r) => r.error ?? '' },
  ];

  return (
    <div className="tc-stack" aria-busy={loading}>
      <p className="ui-muted small" data-testid="stats-days">
        {days.length > 0
          ? `Data for ${days[0]} to ${days[days.length - 1]} (${days.length} days)`
          : 'The machine returned no days for this range.'}
        {/* An empty day (a weekend, a holiday) is not an error: say so instead of a wall of zeros. */}
        {days.length > 0 && derived.active === 0 && data.programs.length === 0
          ? ' · no production was recorded in this range'
          : ''}{' '}
        · units: {u ?? '—'}
        {clipped ? ' · the machine clipped the range to the days it keeps' : ''}
        {loading ? ' · refreshing…' : ''}
      </p>
      <div className="tc-cards" data-testid="stats-summary">
        <Card label="Active" value={duration(derived.active)} />
        <Card
          label="Productive"
          value={derived.active > 0 ? formatPercent(derived.productive / derived.active) : '—'}
        />
        <Card label="Tool on" value={duration(derived.toolOn)} />
        <Card label="Starts, all tools (pierces)" value={num(derived.pierces, 0)} />
        <Card label="Distance, all tools" value={length(derived.distance, u)} />
        <Card label="Programs run" value={num(data.programs.length, 0)} />
        <Card
          label="Errors"
          value={num(data.errors.length, 0)}
          tone={data.errors.length > 0 ? 'bad' : undefined}
        />
      </div>

      <Panel
        title="Consumables"
        actions={
          <CsvButton name={`touchcut-consumable-totals-${tag}`} columns={consTotalCsv} rows={derived.cons} />
        }
        testId="stats-consumables"
      >
        <DataTable
          label="Consumables per tool"
          testId="stats-consumable-totals"
          rowKey={(r) => r.key}
          rows={derived.cons}
          empty="No consumable records in this range."
          columns={[
            { key: 'toolName', label: 'Tool' },
            { key: 'consType', label: 'Type' },
            { key: 'consID', label: 'ID', render: (r) => <span className="mono">{r.consID || '—'}</span> },
            { key: 'pierces', label: 'Pierces', align: 'right', render: (r) => num(r.pierces, 0) },
            { key: 'distance', label: 'Distance', align: 'right', render: (r) => length(r.distance, u) },
            { key: 'time', label: 'Time', align: 'right', render: (r) => duration(r.time) },
            { key: 'records', label: 'Records', align: 'right', render: (r) => num(r.records, 0) },
          ]}
        />
        <details>
          <summary>All consumable records ({data.consumables.length})</summary>
          <div className="ui-row" style={{ margin: '8px 0' }}>
            <CsvButton name={`touchcut-consumables-${tag}`} columns={consCsv} rows={data.consumables} />
          </div>
          <DataTable
            label="Consumable records"
            rowKey={(_r, i) => String(i)}
            rows={data.consumables}
            columns={[
              { key: 'date', label: 'Date', render: (r) => (r.date ?? '').replace('T', ' ') },
              { key: 'toolName', label: 'Tool', render: (r) => r.toolName ?? '—' },
              { key: 'material', label: 'Material', render: (r) => r.material ?? '—' },
              {
                key: 'thickness',
                label: `Thickness (${lu})`,
                align: 'right',
                render: (r) => num(r.thickness, 3),
              },
              { key: 'process', label: 'Process', render: (r) => r.process ?? '—' },
              { key: 'consType', label: 'Type', render: (r) => r.consType ?? '—' },
              { key: 'consID', label: 'ID', render: (r) => r.consID ?? '—' },
              { key: 'pierces', label: 'Pierces', align: 'right', render: (r) => num(r.pierces, 0) },
              {
                key: 'distance',
                label: 'Distance',
                align: 'right',
                render: (r) => length(r.distance ?? 0, u),
              },
              { key: 'time', label: 'Time', align: 'right', render: (r) => duration(r.time ?? 0) },
            ]}
          />
        </details>
      </Panel>

      <Panel
        title="Sessions per user"
        actions={<CsvButton name={`touchcut-sessions-${tag}`} columns={userCsv} rows={derived.users} />}
      >
        <UserBars users={derived.users} />
        <DataTable
          label="Sessions per user"
          rowKey={(r) => r.user}
          rows={derived.users}
          empty="No sessions in this range."
          columns={[
            { key: 'user', label: 'User' },
            { key: 'sessions', label: 'Sessions', align: 'right' },
            { key: 'activeTime', label: 'Active', align: 'right', render: (r) => duration(r.activeTime) },
            {
              key: 'productiveTime',
              label: 'Productive',
              align: 'right',
              render: (r) => duration(r.productiveTime),
            },
            {
              key: 'unproductiveTime',
              label: 'Unproductive',
              align: 'right',
              render: (r) => duration(r.unproductiveTime),
            },
            { key: 'errorTime', label: 'Error', align: 'right', render: (r) => duration(r.errorTime) },
            { key: 'idleTime', label: 'Idle', align: 'right', render: (r) => duration(r.idleTime) },
            {
              key: 'xyMovingTime',
              label: 'XY moving',
              align: 'right',
              render: (r) => duration(r.xyMovingTime),
            },
            { key: 'toolOnTime', label: 'Tool on', align: 'right', render: (r) => duration(r.toolOnTime) },
          ]}
        />
      </Panel>

      <div className="tc-two">
        <Panel
          title={`Programs run (${data.programs.length})`}
          actions={<CsvButton name={`touchcut-programs-${tag}`} columns={progCsv} rows={data.programs} />}
        >
          <DataTable
            label="Programs"
            rowKey={(r) => r.name}
            rows={derived.programs}
            empty="No programs in this range."
            columns={[
              { key: 'name', label: 'Program' },
              { key: 'runs', label: 'Runs', align: 'right' },
              { key: 'last', label: 'Last start', render: (r) => r.last.replace('T', ' ') || '—' },
            ]}
          />
        </Panel>
        <Panel
          title={`Errors (${data.errors.length})`}
          actions={<CsvButton name={`touchcut-errors-${tag}`} columns={errCsv} rows={data.errors} />}
        >
          <DataTable
            label="Errors"
            rowKey={(_r, i) => String(i)}
            rows={data.errors}
            empty="No errors in this range."
            columns={[
              { key: 'errorTime', label: 'When', render: (r) => (r.errorTime ?? '').replace('T', ' ') },
              { key: 'error', label: 'Error', render: (r) => r.error ?? '—' },
            ]}
          />
        </Panel>
      </div>

      <Panel
        title="Tool totals in this range"
        actions={
          <CsvButton
            name={`touchcut-tool-totals-${tag}`}
            columns={[
              { label: 'tool', value: (r: (typeof derived.tools)[number]) => r.name },
              { label: 'time_s', value: (r) => r.time },
              { label: `distance_${lu}`, value: (r) => r.distance },
              { label: 'starts', value: (r) => r.starts },
              { label: 'errors', value: (r) => r.errors },
            ]}
            rows={derived.tools}
          />
        }
      >
        <DataTable
          label="Tool use"
          rowKey={(r) => `${r.tool ?? ''}-${r.name}`}
          rows={derived.tools}
          empty="No tool use in this range."
          columns={[
            { key: 'name', label: 'Tool' },
            { key: 'time', label: 'Time', align: 'right', render: (r) => duration(r.time) },
            { key: 'distance', label: 'Distance', align: 'right', render: (r) => length(r.distance, u) },
            { key: 'starts', label: 'Starts', align: 'right', render: (r) => num(r.starts, 0) },
            { key: 'errors', label: 'Errors', align: 'right', render: (r) => num(r.errors, 0) },
          ]}
        />
      </Panel>

      <div className="tc-two">
        <Panel
          title="Machine totals"
          actions={
            <CsvButton name="touchcut-machine-totals" columns={totalsCsv} rows={totalsRows(data.machine)} />
          }
        >
          <DataTable
            label="Machine totals"
            rowKey={(r) => r.key}
            rows={totalsRows(data.machine)}
            columns={totalsColumns(false)}
            empty="No machine totals."
          />
        </Panel>
        <Panel
          title="Resettable totals"
          actions={
            <CsvButton
              name="touchcut-resettable-totals"
              columns={totalsCsv}
              rows={totalsRows(data.machineResettable)}
            />
          }
        >
          <DataTable
            label="Resettable totals"
            rowKey={(r) => r.key}
            rows={totalsRows(data.machineResettable)}
            columns={totalsColumns(true)}
            empty="No resettable totals."
          />
        </Panel>
      </div>
    </div>
  );
}

function Card(props: { label: string; value: string; tone?: 'bad' }) {
  return (
    <div className="tc-card">
      <div className="ui-muted small">{props.label}</div>
      <div className="tc-card-value" style={props.tone ? { color: `var(--${props.tone})` } : undefined}>
        {props.value}
      </div>
    </div>
  );
}

/** Stacked bars of each user's active time: productive, unproductive, error, idle (+ other, if any). */
function UserBars({ users }: { users: UserTotals[] }) {
  const max = Math.max(1, ...users.map((u) => u.activeTime));
  if (users.length === 0) return null;
  const parts = [...TIME_PARTS, { key: 'otherTime', label: 'Other', color: 'var(--border)' } as const];
  return (
    <figure className="tc-bars" data-testid="stats-user-bars">
      <div className="ui-legend ui-row small">
        {parts.map((p) => (
          <span key={p.key}>
            <i className="tc-swatch" style={{ background: p.color }} /> {p.label}
          </span>
        ))}
      </div>
      {users.map((u) => (
        <div key={u.user} className="tc-bar-row">
          <span className="tc-bar-label">{u.user}</span>
          <div
            className="tc-bar"
            style={{ width: `${(u.activeTime / max) * 100}%` }}
            role="img"
            aria-label={`${u.user}: ${parts.map((p) => `${p.label} ${duration(u[p.key])}`).join(', ')}`}
          >
            {parts.map((p) =>
              u[p.key] > 0 ? (
                <span
                  key={p.key}
                  style={{ flexGrow: u[p.key], background: p.color }}
                  title={`${p.label}: ${duration(u[p.key])}`}
                />
              ) : null,
            )}
          </div>
          <span className="tc-bar-total ui-muted small">{duration(u.activeTime)}</span>
        </div>
      ))}
      <figcaption className="ui-muted small">
        Active time per user, split as TouchCut reports it. XY moving and tool-on time overlap these parts and
        are in the table.
      </figcaption>
    </figure>
  );
}

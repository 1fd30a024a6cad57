import './list.css';
import { Component, memo, type ReactNode } from 'react';
import { familyLabel } from '../../controllers';
import { linkWords } from '../../fleet/contract';
import { getRuntime, type MachineRuntime } from '../../fleet/fleet';
import { useSnapshot } from '../../fleet/react';
import { mostSevereAlarm, type MachineInfo } from '../../fleet/types';
import { Badge, ProgressBar } from '../../ui';
import { useJobWords } from '../../fleet/job-facts';
import { MachineAge } from '../Age';
import { Link } from '../router';
import { cardFields, LINK_TONE, shownState } from '../status';
import type { FleetGroup } from './arrange';

const COLUMNS = ['Machine', 'Family', 'State', 'Job', 'Alarms', 'Link', 'Data'] as const;

/**
 * The dense view: one row per machine. Each row reads its own machine's snapshot (as a tile
 * does); the table re-renders only when the arrangement changes.
 */
export function FleetList({
  groups,
  byId,
}: {
  groups: readonly FleetGroup[];
  byId: ReadonlyMap<string, MachineInfo>;
}) {
  return (
    <div className="fleet-list-wrap">
      <table className="ui-table fleet-list" data-testid="fleet-list">
        <caption className="sr-only">Machines</caption>
        <thead>
          <tr>
            {COLUMNS.map((c) => (
              <th key={c} scope="col">
                {c}
              </th>
            ))}
          </tr>
        </thead>
        {groups.map((g) => (
          <tbody key={g.key} data-testid={g.label === null ? undefined : `fleet-group-${g.key}`}>
            {g.label !== null && (
              <tr className="fleet-list-group">
                <th colSpan={COLUMNS.length} scope="colgroup">
                  {g.label} <span className="ui-muted">({g.ids.length})</span>
                </th>
              </tr>
            )}
            {g.ids.map((id) => {
              const info = byId.get(id);
              return info ? <ListRow key={id} info={info} /> : null;
            })}
          </tbody>
        ))}
      </table>
    </div>
  );
}

const ListRow = memo(function ListRow({ info }: { info: MachineInfo }) {
  const rt = getRuntime(info.id);
  if (!rt) return null;
  return (
    <RowBoundary label={info.name}>
      <RowBody info={info} rt={rt} />
    </RowBoundary>
  );
});

function RowBody({ info, rt }: { info: MachineInfo; rt: MachineRuntime }) {
  const s = useSnapshot(rt, cardFields);
  const job = useJobWords(info.id, s.job);
  const open = s.alarms.filter((a) => !a.acknowledged);
  const worst = mostSevereAlarm(open);
  const shown = shownState(s.activity, s.alarms);
  return (
    <tr
      data-testid={`row-${info.id}`}
      data-activity={shown.activity}
      className={worst?.severity === 'critical' ? 'has-critical' : undefined}
    >
      <td>
        <Link to={`/m/${encodeURIComponent(info.id)}`} className="fleet-list-name">
          {info.name}
        </Link>
        {info.group && (
          <div className="ui-muted small" data-testid="row-group">
            {info.group}
          </div>
        )}
      </td>
      <td className="small">{familyLabel(info.kind)}</td>
      <td>
        <Badge tone={shown.tone} testId="row-activity">
          {shown.words}
        </Badge>
        <div className="small fleet-list-label" title={s.activityLabel}>
          {s.activityLabel}
        </div>
      </td>
      <td className="fleet-list-job">
        {s.job && job ? (
          <>
            <div className="small fleet-list-label" title={job.name}>
              {job.name} · {job.percent}
            </div>
            <ProgressBar value={job.fraction} label={`${info.name} job progress`} />
          </>
        ) : (
          <span className="ui-muted small">No job</span>
        )}
      </td>
      <td className="small" data-testid="row-alarms">
        {worst ? (
          <span
            className={`tone-${worst.severity === 'critical' ? 'bad' : worst.severity === 'warning' ? 'warn' : 'info'} fleet-list-alarm`}
          >
            {worst.severity === 'critical' && <span aria-hidden="true">⚠ </span>}
            {worst.message}
            {open.length > 1 && ` (+${open.length - 1})`}
          </span>
        ) : (
          <span className="ui-muted">—</span>
        )}
      </td>
      <td>
        <Badge tone={LINK_TONE[s.link]} testId="row-link" title={s.problem?.message}>
          {linkWords(s.link)}
        </Badge>
      </td>
      <td>
        <MachineAge rt={rt} />
      </td>
    </tr>
  );
}

/** One broken row never blanks the table (ErrorBoundary's notice is no table row). */
class RowBoundary extends Component<{ label: string; children: ReactNode }, { error: Error | null }> {
  override state: { error: Error | null } = { error: null };

  static getDerivedStateFromError(error: Error): { error: Error } {
    return { error };
  }

  override componentDidCatch(error: Error): void {
    console.error(`[${this.props.label}]`, error);
  }

  override render(): ReactNode {
    if (!this.state.error) return this.props.children;
    return (
      <tr>
        <td colSpan={COLUMNS.length} className="tone-bad">
          <span role="alert" data-testid="error-boundary">
            <strong>{this.props.label}: this row failed</strong> — {this.state.error.message}
          </span>
        </td>
      </tr>
    );
  }
}

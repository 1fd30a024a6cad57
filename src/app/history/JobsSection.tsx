import { useMemo, useState } from 'react';
import {
  Badge,
  Button,
  DataTable,
  Field,
  Panel,
  formatDateTime,
  formatDuration,
  formatPercent,
  type Column,
  type Tone,
} from '../../ui';
import { OUTCOMES, jobsSchema, query, type Job } from './api';
import { QueryProblem } from './QueryProblem';
import type { Range } from './range';
import { useQuery } from './useQuery';

export const JOBS_PAGE = 50;

const OUTCOME_TONE: Record<string, Tone> = {
  finished: 'ok',
  cancelled: 'warn',
  failed: 'bad',
  unknown: 'muted',
  open: 'info',
};

function people(j: Job): string {
  const bits: string[] = [];
  if (j.startedBy) bits.push(`started by ${j.startedBy}`);
  if (j.pausedBy) bits.push(`paused by ${j.pausedBy}`);
  if (j.resumedBy) bits.push(`resumed by ${j.resumedBy}`);
  if (j.stoppedBy) bits.push(`stopped by ${j.stoppedBy}`);
  return bits.join(', ') || '—';
}

const COLUMNS: Column<Job>[] = [
  {
    key: 'machine',
    label: 'Machine',
    render: (j) => <span className="history-machine">{j.machineName}</span>,
  },
  { key: 'name', label: 'Job', render: (j) => j.name ?? <span className="ui-muted">(no name)</span> },
  {
    key: 'start',
    label: 'Started',
    render: (j) => <span className="history-time">{formatDateTime(j.startedAt)}</span>,
  },
  {
    key: 'end',
    label: 'Ended',
    render: (j) => (
      <span className="history-time">{j.endedAt === null ? '—' : formatDateTime(j.endedAt)}</span>
    ),
  },
  {
    key: 'outcome',
    label: 'Outcome',
    render: (j) => (
      <span>
        <Badge tone={OUTCOME_TONE[j.outcome ?? 'open'] ?? 'muted'}>{j.outcome ?? 'running now'}</Badge>
        {j.endAlarm && <span className="ui-muted"> {j.endAlarm}</span>}
      </span>
    ),
  },
  { key: 'running', label: 'Running', align: 'right', render: (j) => formatDuration(j.runningS) },
  { key: 'paused', label: 'Paused', align: 'right', render: (j) => formatDuration(j.pausedS) },
  {
    key: 'progress',
    label: 'Progress',
    align: 'right',
    render: (j) => (j.progress === null ? '—' : formatPercent(j.progress)),
  },
  { key: 'who', label: 'Who', render: (j) => <span className="history-who">{people(j)}</span> },
];

interface Filters {
  machine: string;
  family: string;
  outcome: string;
  q: string;
}
const NO_FILTERS: Filters = { machine: '', family: '', outcome: '', q: '' };

/** Jobs that overlap the range, newest first, filtered, paged, with a CSV of every match. */
export function JobsSection(props: {
  range: Range | null;
  tick: number;
  machines: ReadonlyArray<{ id: string; name: string }>;
  families: readonly string[];
}) {
  const [draft, setDraft] = useState<Filters>(NO_FILTERS);
  const [filters, setFilters] = useState<Filters>(NO_FILTERS);
  const [offset, setOffset] = useState(0);
  const base = useMemo(
    () => ({
      machine: filters.machine,
      family: filters.family,
      outcome: filters.outcome,
      q: filters.q.trim(),
      from: props.range?.from,
      to: props.range?.to,
    }),
    [filters, props.range],
  );
  const url = props.range ? `/api/history/jobs${query({ ...base, limit: JOBS_PAGE, offset })}` : null;
  const jobs = useQuery(jobsSchema, url, 'jobs', props.tick);
  const total = jobs.data?.total ?? 0;
  const set = (k: keyof Filters) => (v: string) => setDraft((d) => ({ ...d, [k]: v }));
  const apply = (f: Filters) => {
    setOffset(0);
    setFilters(f);
  };
  const first = jobs.data ? jobs.data.offset + 1 : 0;
  const last = jobs.data ? jobs.data.offset + jobs.data.jobs.length : 0;

  return (
    <Panel
      title="Jobs"
      testId="history-jobs"
      actions={
        <a
          className="ui-button secondary history-csv"
          href={`/api/history/jobs.csv${query(base)}`}
          download="shopdeck-jobs.csv"
          data-testid="history-jobs-csv"
        >
          Export CSV
        </a>
      }
    >
      <form
        className="history-filters"
        onSubmit={(e) => {
          e.preventDefault();
          apply(draft);
        }}
      >
        <Field label="Machine">
          {(id) => (
            <select
              id={id}
              className="ui-input"
              value={draft.machine}
              onChange={(e) => set('machine')(e.target.value)}
            >
              <option value="">All machines</option>
              {props.machines.map((m) => (
                <option key={m.id} value={m.id}>
                  {m.name}
                </option>
              ))}
            </select>
          )}
        </Field>
        <Field label="Family">
          {(id) => (
            <select
              id={id}
              className="ui-input"
              value={draft.family}
              onChange={(e) => set('family')(e.target.value)}
            >
              <option value="">All families</option>
              {props.families.map((f) => (
                <option key={f} value={f}>
                  {f}
                </option>
              ))}
            </select>
          )}
        </Field>
        <Field label="Outcome">
          {(id) => (
            <select
              id={id}
              className="ui-input"
              value={draft.outcome}
              onChange={(e) => set('outcome')(e.target.value)}
            >
              <option value="">Any outcome</option>
              <option value="open">running now</option>
              {OUTCOMES.map((o) => (
                <option key={o} value={o}>
                  {o}
                </option>
              ))}
            </select>
          )}
        </Field>
        <Field label="Text">
          {(id) => (
            <input
              id={id}
              className="ui-input"
              type="search"
              value={draft.q}
              placeholder="job, person or alarm"
              autoCapitalize="off"
              onChange={(e) => set('q')(e.target.value)}
            />
          )}
        </Field>
        <div className="ui-row history-filter-actions">
          <Button type="submit" variant="primary">
            Apply filters
          </Button>
          <Button
            onClick={() => {
              setDraft(NO_FILTERS);
              apply(NO_FILTERS);
            }}
          >
            Clear
          </Button>
        </div>
      </form>
      <QueryProblem q={jobs} what="the jobs" />
      {jobs.data && (
        <>
          <DataTable
            columns={COLUMNS}
            rows={jobs.data.jobs}
            rowKey={(j) => String(j.id)}
            empty="No job in this range matches these filters."
            caption={total === 0 ? undefined : `Jobs ${first}–${last} of ${total}, newest first`}
            label="Jobs"
            testId="history-jobs-table"
          />
          {total > JOBS_PAGE && (
            <nav className="ui-row history-paging" aria-label="Pages of jobs">
              <Button disabled={offset === 0} onClick={() => setOffset(Math.max(0, offset - JOBS_PAGE))}>
                Newer
              </Button>
              <span>
                Page {Math.floor(offset / JOBS_PAGE) + 1} of {Math.ceil(total / JOBS_PAGE)}
              </span>
              <Button disabled={offset + JOBS_PAGE >= total} onClick={() => setOffset(offset + JOBS_PAGE)}>
                Older
              </Button>
            </nav>
          )}
        </>
      )}
    </Panel>
  );
}

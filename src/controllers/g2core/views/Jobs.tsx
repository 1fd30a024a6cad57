import { useState } from 'react';
import { CommandButton, useStoreSelect } from '../../../fleet/react';
import { Badge, Button, DataTable, Notice, Panel, ProgressBar, formatDateTime, type Tone } from '../../../ui';
import { describeError } from '../../../fleet/errors';
import { useJobs } from '../queries';
import { describeStatus, type G2coreSession } from '../session';
import type { Job, JobState } from '../wire';
import { Controls, JobProgress, StatBadge } from './common';

const STATE_TONE: Record<JobState, Tone> = {
  queued: 'muted',
  running: 'info',
  paused: 'paused',
  done: 'ok',
  killed: 'warn',
  error: 'bad',
  unknown: 'muted',
};

const SAMPLE = ['G21 G90', 'G0 X10 Y10', 'G1 X60 F600', 'G1 Y60', 'G1 X10', 'G1 Y10', 'G0 X0 Y0'].join('\n');

/** Run G-code files as jobs: upload or paste, the queue, progress (lines done / total). */
export function JobsTab({ session }: { session: G2coreSession }) {
  const notice = useStoreSelect(session.detail, (d) => d.notice);
  // The queue is an on-demand read (query key ['jobs']), shared with the session's slow poll.
  const list = useJobs(session);
  const jobs = list.data ?? [];
  const jobsError = list.error ? describeError(list.error) : null;
  const { commands: runner, snapshot } = session.ctx;
  const [name, setName] = useState('part.nc');
  const [gcode, setGcode] = useState('');
  const [file, setFile] = useState<File | null>(null);
  const queued = jobs
    .filter((j) => j.state.state === 'queued')
    .sort((a, b) => (a.position ?? 0) - (b.position ?? 0));

  const columns = [
    {
      key: 'name',
      label: 'Job',
      render: (j: Job) => <span data-testid={`g2-job-name-${j.id}`}>{j.name ?? `job ${j.id}`}</span>,
    },
    {
      key: 'state',
      label: 'State',
      render: (j: Job) => (
        <span data-testid={`g2-job-state-${j.id}`}>
          <Badge
            tone={STATE_TONE[j.state.state]}
            title={
              j.error ? `${j.error.description ?? ''} ${j.error.additional_description ?? ''}` : undefined
            }
          >
            {j.state.state === 'unknown' ? `unknown (raw ${j.state.raw})` : j.state.state}
          </Badge>
          {j.error && j.error.code !== 207 && (
            <span
              className="ui-muted"
              style={{ display: 'block', color: 'var(--bad)' }}
              data-testid={`g2-job-error-${j.id}`}
            >
              {describeStatus(j.error)}
            </span>
          )}
        </span>
      ),
    },
    {
      key: 'lines',
      label: 'Lines',
      align: 'right' as const,
      render: (j: Job) => (
        <div style={{ minWidth: 120 }}>
          {j.done ?? 0} / {j.lines ?? '—'}
          {j.lines ? <ProgressBar value={(j.done ?? 0) / j.lines} label={`progress of ${j.name}`} /> : null}
        </div>
      ),
    },
    {
      key: 'time',
      label: 'Started / finished',
      render: (j: Job) => (
        <span className="ui-muted">
          {j.started ? formatDateTime(j.started) : '—'}
          {j.finished ? ` → ${formatDateTime(j.finished)}` : ''}
        </span>
      ),
    },
    {
      key: 'actions',
      label: <span className="sr-only">Actions</span>,
      render: (j: Job) => {
        if (j.state.state !== 'queued') return null;
        const i = queued.indexOf(j);
        return (
          <div className="ui-row">
            <CommandButton
              runner={runner}
              snapshot={snapshot}
              command={session.runJob}
              args={{ id: j.id, name: j.name ?? `job ${j.id}` }}
              variant="primary"
              testId={`g2-job-run-${j.id}`}
            >
              Start
            </CommandButton>
            {i > 0 && (
              <CommandButton
                runner={runner}
                snapshot={snapshot}
                command={session.moveJob}
                args={{ id: j.id, position: i - 1 }}
                label="Move up in the queue"
              >
                <span aria-hidden="true">↑</span>
              </CommandButton>
            )}
            {i >= 0 && i < queued.length - 1 && (
              <CommandButton
                runner={runner}
                snapshot={snapshot}
                command={session.moveJob}
                args={{ id: j.id, position: i + 1 }}
                label="Move down in the queue"
              >
                <span aria-hidden="true">↓</span>
              </CommandButton>
            )}
            <CommandButton
              runner={runner}
              snapshot={snapshot}
              command={session.removeJob}
              args={{ id: j.id }}
            >
              Remove
            </CommandButton>
          </div>
        );
      },
    },
  ];

  return (
    <div style={{ display: 'grid', gap: 14 }}>
      <Panel title="Current job" actions={<StatBadge session={session} />}>
        <JobProgress session={session} />
        <div style={{ marginTop: 10 }}>
          <Controls session={session} />
        </div>
      </Panel>
      <Panel title="Queue" testId="g2-job-queue">
        {jobsError && (
          <Notice tone="warn" title="Could not read the job queue">
            {jobsError}
          </Notice>
        )}
        {notice && <Notice tone="info">{notice}</Notice>}
        <p className="ui-muted">
          A job never starts by itself: the next one waits for an operator to check the stock and press Start.
        </p>
        <DataTable
          columns={columns}
          rows={jobs}
          rowKey={(j) => j.id}
          empty="No jobs. Upload a G-code file or paste one below."
          testId="g2-jobs"
        />
      </Panel>
      <Panel title="Add a job">
        <div className="ui-row" style={{ marginBottom: 10 }}>
          <input
            className="ui-input"
            type="file"
            accept=".nc,.gcode,.ngc,.gc,.tap,.txt"
            aria-label="G-code file"
            data-testid="g2-job-file"
            onChange={(e) => setFile(e.target.files?.[0] ?? null)}
          />
          {file && (
            <CommandButton
              runner={runner}
              snapshot={snapshot}
              command={session.queueJob}
              args={{ name: file.name, file }}
              onDone={() => setFile(null)}
              testId="g2-job-upload"
            >
              {`Queue ${file.name}`}
            </CommandButton>
          )}
        </div>
        <div className="ui-field">
          <label htmlFor="g2-job-name">Name</label>
          <input
            id="g2-job-name"
            className="ui-input"
            value={name}
            onChange={(e) => setName(e.target.value)}
            data-testid="g2-job-name"
          />
        </div>
        <div className="ui-field">
          <label htmlFor="g2-job-gcode">G-code</label>
          <textarea
            id="g2-job-gcode"
            className="g2-textarea"
            value={gcode}
            placeholder={SAMPLE}
            onChange={(e) => setGcode(e.target.value)}
            data-testid="g2-job-gcode"
          />
        </div>
        <div className="ui-row">
          {gcode.trim() === '' ? (
            <Button disabled title="Paste or type G-code first">
              Queue G-code
            </Button>
          ) : (
            <CommandButton
              runner={runner}
              snapshot={snapshot}
              command={session.queueJob}
              args={{ name: name.trim() || 'job.nc', gcode }}
              onDone={() => setGcode('')}
              testId="g2-job-queue-text"
            >
              Queue G-code
            </CommandButton>
          )}
          {gcode.trim() === '' && (
            <button type="button" className="ui-button secondary" onClick={() => setGcode(SAMPLE)}>
              Use the sample square
            </button>
          )}
        </div>
      </Panel>
    </div>
  );
}

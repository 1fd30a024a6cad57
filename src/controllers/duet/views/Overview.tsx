import type { TabProps } from '../../../fleet/contract';
import { JobFacts } from '../../../fleet/JobFacts';
import { useJobWords } from '../../../fleet/job-facts';
import { CommandButton, useNow, useSnapshot, useStoreSelect } from '../../../fleet/react';
import {
  Badge,
  DataTable,
  KeyValues,
  Panel,
  ProgressBar,
  formatBytes,
  formatDuration,
  formatNumber,
  formatPercent,
  formatTime,
  type Series,
  type Tone,
} from '../../../ui';
import { TimeSeriesChart } from '../../../ui/TimeSeriesChart';
import { earlierNote, useEarlierTemperatures, withEarlier } from '../../../fleet/server-temperatures';
import { baseName } from '../client';
import type { DuetSession } from '../session';
import { heaterName, isPrinting, jobProgress, statusWords } from '../snapshot';
import { DuetFrame, Thumbnail } from './common';

const STATUS_TONE: Record<string, Tone> = {
  disconnected: 'bad',
  starting: 'info',
  updating: 'info',
  off: 'muted',
  halted: 'bad',
  pausing: 'paused',
  paused: 'paused',
  resuming: 'ok',
  cancelling: 'warn',
  processing: 'ok',
  simulating: 'ok',
  busy: 'info',
  changingTool: 'info',
  idle: 'muted',
};

/** Status, job and job control, heaters with chart, axes, fans, tools, board, volumes. */
export function Overview({ session }: TabProps<DuetSession>) {
  return (
    <DuetFrame session={session}>
      <div className="ui-grid" data-testid="duet-overview">
        <JobPanel session={session} />
        {/* Two grid columns: the heater table and its chart need the width on a tablet. */}
        <div className="ui-span-2" style={{ minWidth: 0, display: 'grid' }}>
          <HeatersPanel session={session} />
        </div>
        <AxesPanel session={session} />
        <MachinePanel session={session} />
      </div>
    </DuetFrame>
  );
}

function JobPanel({ session }: { session: DuetSession }) {
  const ctx = session.ctx;
  const now = useNow(1000);
  const snap = useSnapshot(ctx, (s) => ({ link: s.link, label: s.activityLabel }));
  const job = useSnapshot(ctx, (s) => s.job);
  const words = useJobWords(session.machine.id, job);
  const d = useStoreSelect(session.store, (s) => {
    const m = s.model;
    return {
      status: m?.state.status ?? null,
      file: m?.job.file ?? null,
      progress: m ? jobProgress(m) : null,
      layer: m?.job.layer ?? null,
      duration: m?.job.duration ?? null,
      timesLeft: m?.job.timesLeft ?? null,
      lastFileName: m?.job.lastFileName ?? null,
      displayMessage: m?.state.displayMessage ?? '',
      printing: m ? isPrinting(m.state.status) : false,
    };
  });
  const status = d.status;
  const left = d.timesLeft?.file ?? d.timesLeft?.filament ?? d.timesLeft?.slicer ?? null;
  return (
    <Panel title="Job" testId="duet-job">
      <div className="ui-row" style={{ marginBottom: 10 }}>
        <Badge tone={status ? (STATUS_TONE[status] ?? 'muted') : 'muted'} testId="duet-status">
          {status ? statusWords(status) : snap.label}
        </Badge>
        {d.displayMessage ? <span className="ui-muted">{d.displayMessage}</span> : null}
      </div>
      {d.printing && d.file?.fileName ? (
        <>
          <div className="ui-row" style={{ alignItems: 'flex-start', marginBottom: 8 }}>
            <Thumbnail
              thumb={d.file.thumbnails.find((t) => t.data) ?? null}
              size={72}
              alt={`${baseName(d.file.fileName)} thumbnail`}
            />
            <div style={{ flex: 1, minWidth: 0 }}>
              <div
                style={{ fontSize: 20, fontWeight: 600, overflowWrap: 'anywhere' }}
                data-testid="duet-job-name"
              >
                {baseName(d.file.fileName)}
              </div>
              <div className="ui-muted">{d.file.generatedBy ?? ''}</div>
            </div>
          </div>
          <div className="ui-row" style={{ flexWrap: 'nowrap' }}>
            <div style={{ flex: 1 }}>
              <ProgressBar value={words?.fraction ?? null} label="Job progress" />
            </div>
            <div style={{ fontSize: 28, fontWeight: 700 }} data-testid="duet-job-progress">
              {words?.percent ?? '—'}
            </div>
          </div>
          {/* The server's job record, as every view says it (fleet/job-facts.ts). */}
          <JobFacts machine={session.machine.id} job={job} bar={false} />
          <KeyValues
            items={[
              ['Layer', d.layer !== null ? `${d.layer} of ${d.file.numLayers || '?'}` : '—'],
              ['Print time', formatDuration(d.duration)],
              ['Left (file)', formatDuration(d.timesLeft?.file)],
              ['Left (filament)', formatDuration(d.timesLeft?.filament)],
              ['Left (slicer)', formatDuration(d.timesLeft?.slicer)],
              ['Estimated finish', left !== null ? formatTime(now + left * 1000) : '—'],
            ]}
          />
        </>
      ) : (
        <p className="ui-muted">
          No job running.{d.lastFileName ? ` Last: ${baseName(d.lastFileName)}.` : ''} Start a file from the
          Files tab.
        </p>
      )}
    </Panel>
  );
}

function HeatersPanel({ session }: { session: DuetSession }) {
  const ctx = session.ctx;
  const now = useNow(2000);
  // Select stable references only (the model's own objects, kept by unchanged frames); derive in render.
  const m = useStoreSelect(session.store, (s) =>
    s.model ? { heat: s.model.heat, tools: s.model.tools } : null,
  );
  const rows = m
    ? m.heat.heaters.flatMap((h, i) =>
        h
          ? [
              {
                i,
                name: heaterName(m, i),
                current: h.current <= -273 ? null : h.current,
                active: h.active,
                standby: h.standby,
                state: h.state,
              },
            ]
          : [],
      )
    : [];
  const history = useStoreSelect(session.store, (s) => s.history);
  // The last minutes the console's server kept (by heater index, as `history`), then the live points.
  const earlier = useEarlierTemperatures(ctx.machine.id, ctx.now);
  const series: Series[] = m
    ? rows.map((r) => ({
        name: r.name,
        points: withEarlier(
          earlier.state === 'ok' ? earlier.byKey.get(String(r.i))?.points : undefined,
          history[r.i] ?? [],
        ),
      }))
    : // No model yet (connecting): the server's readings by the names it kept.
      earlier.state === 'ok'
      ? [...earlier.byKey.values()].map((e) => ({ name: e.name, points: e.points }))
      : [];
  return (
    <Panel title="Heaters" testId="duet-heaters">
      <DataTable
        rowKey={(r) => String(r.i)}
        rows={rows}
        empty="No heaters configured."
        columns={[
          { key: 'name', label: 'Heater' },
          {
            key: 'current',
            label: 'Current',
            align: 'right',
            render: (r) => (r.current === null ? 'no sensor' : formatNumber(r.current, 1, '°C')),
          },
          {
            key: 'set',
            label: 'Active / standby',
            align: 'right',
            render: (r) => `${formatNumber(r.active, 0)} / ${formatNumber(r.standby, 0)} °C`,
          },
          {
            key: 'state',
            label: 'State',
            render: (r) =>
              r.state === 'fault' ? (
                <span className="ui-row">
                  <Badge tone="bad">fault</Badge>
                  <CommandButton
                    runner={ctx.commands}
                    snapshot={ctx.snapshot}
                    command={session.cmd.heaterReset}
                    args={{ heater: r.i }}

                    hideWhenNotAllowed
                  >
                    Reset fault
                  </CommandButton>
                </span>
              ) : (
                <Badge tone={r.state === 'active' ? 'ok' : r.state === 'standby' ? 'info' : 'muted'} plain>
                  {r.state}
                </Badge>
              ),
          },
        ]}
      />
      <TimeSeriesChart
        series={series}
        windowMs={10 * 60_000}
        now={now}
        unit="°C"
        height={160}
        testId="duet-temp-chart"
        note={earlierNote(earlier)}
      />
    </Panel>
  );
}

function AxesPanel({ session }: { session: DuetSession }) {
  const s = useStoreSelect(session.store, (st) => ({
    move: st.model?.move ?? null,
    fans: st.model?.fans ?? null,
    tools: st.model?.tools ?? null,
    currentTool: st.model?.state.currentTool ?? -1,
  }));
  const d = {
    axes: (s.move?.axes ?? []).flatMap((a) => (a && a.visible ? [a] : [])),
    fans: (s.fans ?? []).flatMap((f, i) => (f ? [{ ...f, i }] : [])),
    tools: (s.tools ?? []).flatMap((t) => (t ? [t] : [])),
    currentTool: s.currentTool,
  };
  return (
    <Panel title="Axes, fans, tools" testId="duet-axes">
      <DataTable
        rowKey={(a) => a.letter}
        rows={d.axes}
        columns={[
          { key: 'letter', label: 'Axis' },
          { key: 'user', label: 'User', align: 'right', render: (a) => formatNumber(a.userPosition, 2) },
          {
            key: 'machine',
            label: 'Machine',
            align: 'right',
            render: (a) => formatNumber(a.machinePosition, 2),
          },
          {
            key: 'homed',
            label: 'Homed',
            render: (a) => (
              <Badge tone={a.homed ? 'ok' : 'warn'} plain>
                {a.homed ? 'yes' : 'no'}
              </Badge>
            ),
          },
        ]}
      />
      <DataTable
        rowKey={(f) => String(f.i)}
        rows={d.fans}
        empty="No fans."
        columns={[
          { key: 'name', label: 'Fan', render: (f) => f.name || `Fan ${f.i}` },
          { key: 'value', label: 'Speed', align: 'right', render: (f) => formatPercent(f.actualValue) },
          {
            key: 'rpm',
            label: 'RPM',
            align: 'right',
            render: (f) => (f.rpm !== null && f.rpm >= 0 ? String(f.rpm) : '—'),
          },
        ]}
      />
      <DataTable
        rowKey={(t) => String(t.number)}
        rows={d.tools}
        empty="No tools."
        columns={[
          {
            key: 'number',
            label: 'Tool',
            render: (t) =>
              `T${t.number}${t.name ? ` ${t.name}` : ''}${t.number === d.currentTool ? ' (selected)' : ''}`,
          },
          { key: 'state', label: 'State', render: (t) => t.state },
          { key: 'heaters', label: 'Heaters', render: (t) => t.heaters.join(', ') || '—' },
        ]}
      />
    </Panel>
  );
}

function MachinePanel({ session }: { session: DuetSession }) {
  const s = useStoreSelect(session.store, (st) => ({
    board: st.model?.boards[0] ?? null,
    dsf: st.model?.sbc?.dsf?.version ?? null,
    mode: st.model?.state.machineMode ?? null,
    volumes: st.model?.volumes ?? null,
  }));
  const d = { ...s, volumes: (s.volumes ?? []).flatMap((v, i) => (v ? [{ ...v, i }] : [])) };
  const b = d.board;
  return (
    <Panel title="Board and storage" testId="duet-board">
      <KeyValues
        items={[
          ['Board', b?.name ?? '—'],
          ['Firmware', b ? `${b.firmwareName ?? ''} ${b.firmwareVersion ?? ''}`.trim() || '—' : '—'],
          ['DSF', d.dsf ?? 'standalone'],
          ['Mode', d.mode ?? '—'],
          [
            'MCU temperature',
            b?.mcuTemp
              ? `${formatNumber(b.mcuTemp.current, 1, '°C')} (${formatNumber(b.mcuTemp.min, 1)} – ${formatNumber(b.mcuTemp.max, 1)})`
              : '—',
          ],
          [
            'Input voltage',
            b?.vIn
              ? `${formatNumber(b.vIn.current, 1, 'V')} (${formatNumber(b.vIn.min, 1)} – ${formatNumber(b.vIn.max, 1)})`
              : '—',
          ],
        ]}
      />
      <DataTable
        rowKey={(v) => String(v.i)}
        rows={d.volumes}
        empty="No volumes."
        columns={[
          { key: 'path', label: 'Volume', render: (v) => v.name || v.path || `Volume ${v.i}` },
          {
            key: 'free',
            label: 'Free',
            align: 'right',
            render: (v) => (v.mounted ? formatBytes(v.freeSpace) : 'not mounted'),
          },
          { key: 'capacity', label: 'Size', align: 'right', render: (v) => formatBytes(v.capacity) },
        ]}
      />
    </Panel>
  );
}

import { useLayoutEffect, useMemo, useRef, useState } from 'react';
import { Panel, ScrollRegion, formatDateTime, formatDuration } from '../../ui';
import { dateTimeFormat } from '../../ui/locale';
import { query, statesSchema } from './api';
import { KIND_WORDS, hourTicks, layoutStrip, type Segment, type SegmentKind } from './layout';
import { QueryProblem } from './QueryProblem';
import type { Range } from './range';
import { useQuery } from './useQuery';

const LEGEND: SegmentKind[] = ['running', 'paused', 'idle', 'alarm', 'offline', 'unknown', 'unrecorded'];
const W = 1000;

function tickLabel(t: number, day: boolean, multiDay: boolean): string {
  if (day && multiDay) return dateTimeFormat({ weekday: 'short', day: 'numeric' }).format(t);
  if (new Date(t).getMinutes() !== 0) return dateTimeFormat({ hour: 'numeric', minute: '2-digit' }).format(t);
  return dateTimeFormat({ hour: 'numeric' }).format(t);
}

export function segmentText(machineName: string, s: Segment): string {
  const what = KIND_WORDS[s.kind] + (s.alarm ? `: ${s.alarm}` : '');
  const till = s.open ? `${formatDateTime(s.to)} (still so)` : formatDateTime(s.to);
  return `${machineName} — ${what}, ${formatDateTime(s.from)} to ${till} (${formatDuration((s.to - s.from) / 1000)})`;
}

/** A strip per machine over the range, coloured by state; tap or point at a part for its times. */
export function TimelineSection(props: { range: Range | null; tick: number; now: number }) {
  const { range, now } = props;
  const url = range ? `/api/history/states${query({ from: range.from, to: range.to })}` : null;
  const states = useQuery(statesSchema, url, 'timeline', props.tick);
  const [picked, setPicked] = useState<string | null>(null);
  const data = states.data;
  const strips = useMemo(
    () =>
      data
        ? data.machines.map((m) => ({
            machine: m.machine,
            name: m.machineName,
            segments: layoutStrip(m.intervals, data.from, data.to, now),
          }))
        : [],
    [data, now],
  );
  const ticks = useMemo(() => (data ? hourTicks(data.from, data.to, 8) : []), [data]);
  const multiDay = data ? data.to - data.from > 86_400_000 : false;
  // A narrow screen scrolls the strips: bring "now" into view rather than the range's start.
  const scroller = useRef<HTMLDivElement>(null);
  useLayoutEffect(() => {
    const el = scroller.current;
    if (!el || !data || el.scrollWidth <= el.clientWidth) return;
    const at = Math.min(1, Math.max(0, (now - data.from) / (data.to - data.from)));
    el.scrollLeft = Math.max(0, at * el.scrollWidth - el.clientWidth * 0.9);
  }, [data, now]);

  return (
    <Panel
      title="Timeline"
      testId="history-timeline"
      actions={
        range && (
          <a
            className="ui-button secondary history-csv"
            href={`/api/history/states.csv${query({ from: range.from, to: range.to })}`}
            download="shopdeck-states.csv"
          >
            Export CSV
          </a>
        )
      }
    >
      <ul className="history-legend" aria-label="Legend">
        {LEGEND.map((k) => (
          <li key={k}>
            <span className={`history-swatch seg-${k}`} aria-hidden="true" />
            {KIND_WORDS[k]}
          </li>
        ))}
      </ul>
      <QueryProblem q={states} what="the timeline" />
      {data?.truncated && (
        <p className="ui-muted small">Too many changes in this range: the timeline is cut short.</p>
      )}
      {data && strips.length === 0 && <p className="ui-muted">No machine to show.</p>}
      {data && strips.length > 0 && (
        <ScrollRegion className="history-timeline-scroll" label="Timeline, per machine" scrollRef={scroller}>
          <div className="history-timeline">
            <div className="history-ticks" aria-hidden="true">
              {ticks.map((t) => (
                <span key={t.t} className={t.day ? 'day' : ''} style={{ left: `${t.left * 100}%` }}>
                  {tickLabel(t.t, t.day, multiDay)}
                </span>
              ))}
            </div>
            {strips.map((s) => (
              <div className="history-strip-row" key={s.machine} data-testid={`history-strip-${s.machine}`}>
                <div className="history-strip-name">{s.name}</div>
                <svg
                  className="history-strip"
                  viewBox={`0 0 ${W} 10`}
                  preserveAspectRatio="none"
                  role="img"
                  aria-label={`${s.name}: ${summary(s.segments)}`}
                >
                  {ticks.map((t) => (
                    <line
                      key={t.t}
                      className="history-gridline"
                      x1={t.left * W}
                      x2={t.left * W}
                      y1={0}
                      y2={10}
                    />
                  ))}
                  {s.segments.map((seg) => (
                    <rect
                      key={`${seg.from}-${seg.kind}`}
                      className={`seg seg-${seg.kind}`}
                      data-state={seg.kind}
                      x={seg.left * W}
                      y={0}
                      width={seg.width * W}
                      height={10}
                      shapeRendering="crispEdges"
                      onClick={() => setPicked(segmentText(s.name, seg))}
                    >
                      <title>{segmentText(s.name, seg)}</title>
                    </rect>
                  ))}
                </svg>
              </div>
            ))}
          </div>
        </ScrollRegion>
      )}
      {picked && (
        <p className="history-picked" aria-live="polite" data-testid="history-picked">
          {picked}
        </p>
      )}
    </Panel>
  );
}

/** Time per state in words, for a screen reader (the picture's text). */
function summary(segments: readonly Segment[]): string {
  const sums = new Map<SegmentKind, number>();
  for (const s of segments)
    if (s.kind !== 'future') sums.set(s.kind, (sums.get(s.kind) ?? 0) + (s.to - s.from));
  const parts = [...sums.entries()]
    .sort((a, b) => b[1] - a[1])
    .map(([k, ms]) => `${KIND_WORDS[k]} ${formatDuration(ms / 1000)}`);
  return parts.join(', ') || 'nothing recorded';
}

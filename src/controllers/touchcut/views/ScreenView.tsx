import { useEffect, useRef, useState } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { useNow, useSnapshot, useStoreSelect } from '../../../fleet/react';
import { Button, EmptyState, Notice, formatAge, formatTime } from '../../../ui';
import { safeImageBlob } from '../../../ui/safe-url';
import { THUMBNAIL_INTERVAL_MS } from '../feeds';
import type { TouchcutSession } from '../session';
import { READ_ONLY, useObjectUrl } from './common';

/**
 * Live view of the TouchCut screen (`rest/v1/screenshot`): at most one request per second for the
 * machine, only while this view is on screen and the page visible (ScreenshotFeed), with its age,
 * pause and full screen. Only a blob of a raster image type becomes a `blob:` URL (the client
 * checks the PNG signature; this is the last gate): an HTML or SVG "screenshot" opened in a new
 * tab would run in the console's origin.
 */
export function ScreenView({ session }: TabProps<TouchcutSession>) {
  const [paused, setPaused] = useState(false);
  const { blob, at, error } = useStoreSelect(session.screenshot.store, (s) => ({
    blob: s.blob,
    at: s.at,
    error: s.error,
  }));
  // While paused, keep showing the frame we had (a fleet tile may still refresh the shared feed).
  const [frozen, setFrozen] = useState<{ blob: Blob | null; at: number | null } | null>(null);
  useEffect(() => {
    if (paused) return;
    return session.screenshot.subscribe();
  }, [session, paused]);
  const shown = paused && frozen ? frozen : { blob, at };
  const url = useObjectUrl(safeImageBlob(shown.blob));
  const now = useNow(1000);
  const box = useRef<HTMLDivElement>(null);
  const simulated = useSnapshot(session.ctx, () => session.machine.simulated);
  const age = shown.at === null ? null : Math.max(0, now - shown.at);
  // Tablets without the Fullscreen API for elements (iPad Safari) get a CSS full-window view instead.
  const [maximized, setMaximized] = useState(false);
  const fullScreen = () => {
    const el = box.current;
    if (!el) return;
    if (document.fullscreenElement) {
      void document.exitFullscreen();
      return;
    }
    if (typeof el.requestFullscreen === 'function')
      void el.requestFullscreen().catch(() => setMaximized(true));
    else setMaximized(true);
  };
  return (
    <div className="tc-stack" data-testid="touchcut-screen">
      <div className="ui-row">
        <Button
          variant={paused ? 'primary' : 'secondary'}
          onClick={() => {
            if (!paused) setFrozen({ blob, at });
            setPaused(!paused);
          }}
          data-testid="screen-pause"
          aria-pressed={paused}
        >
          {paused ? 'Resume live view' : 'Pause'}
        </Button>
        <Button onClick={fullScreen} data-testid="screen-fullscreen">
          Full screen
        </Button>
        <span
          className={`tc-age${age !== null && age > 5000 ? ' stale' : ''}`}
          data-testid="screen-age"
          title={formatTime(shown.at)}
        >
          {paused ? 'Paused · ' : ''}
          {shown.at === null ? 'no image yet' : `image from ${formatAge(shown.at, now)}`}
        </span>
      </div>
      {error && !paused && <Notice tone="warn">{error}</Notice>}
      <div ref={box} className={`tc-screen${maximized ? ' tc-screen-max' : ''}`}>
        {maximized && (
          <Button className="tc-screen-close" onClick={() => setMaximized(false)} data-testid="screen-close">
            Close full screen
          </Button>
        )}
        {url ? (
          <img
            src={url}
            alt={`TouchCut screen${simulated ? ' (simulated)' : ''}, ${formatAge(shown.at, now)}`}
            data-testid="screen-image"
          />
        ) : (
          <EmptyState>Waiting for the first screenshot…</EmptyState>
        )}
        {simulated && <span className="tc-screen-tag">SIMULATED</span>}
      </div>
      <p className="ui-muted small">
        TouchCut serves a new screenshot at most once a second; the live view asks no more often than that and
        stops while this page is hidden.
      </p>
      {READ_ONLY}
    </div>
  );
}

/** Fleet tile thumbnail: refreshed every 10 s at most (shares the machine's screenshot feed). */
export function ScreenThumbnail({ session }: TabProps<TouchcutSession>) {
  const { blob, at } = useStoreSelect(session.screenshot.store, (s) => ({ blob: s.blob, at: s.at }));
  const link = useSnapshot(session.ctx, (s) => s.link);
  useEffect(() => session.screenshot.subscribe(THUMBNAIL_INTERVAL_MS), [session]);
  const url = useObjectUrl(safeImageBlob(blob));
  const now = useNow(5000);
  if (!url || link !== 'online') return null;
  return (
    <div className="tc-thumb" data-testid="touchcut-thumbnail">
      <img src={url} alt="TouchCut screen thumbnail" loading="lazy" />
      <span className="ui-muted small">{formatAge(at, now)}</span>
    </div>
  );
}

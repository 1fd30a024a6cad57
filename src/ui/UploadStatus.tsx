import type { ReactNode } from 'react';
import { Button, Notice, ProgressBar } from './components';
import { formatBytes } from './format';
import type { UploadState } from './upload-state';

/**
 * The one upload UI: name and target, a progress bar with bytes, what is being checked, the
 * outcome in words, and Cancel while the transfer runs (when the family can cancel).
 */
export function UploadStatus(props: {
  state: UploadState;
  /** Offered while the transfer runs; absent when this upload cannot be cancelled. */
  onCancel?: () => void;
  /** What "verifying" means here ("checking the SD card…"). */
  verifyingText?: ReactNode;
  doneTitle?: string;
  failedTitle?: string;
  /** On the root; the Cancel button gets `<testId>-cancel`. */
  testId?: string;
}) {
  const s = props.state;
  if (s.phase === 'idle') return null;
  const fraction = s.total > 0 ? s.loaded / s.total : null;
  return (
    <div className="ui-upload" data-testid={props.testId} data-phase={s.phase}>
      <div className="ui-row">
        <span className="ui-upload-name">
          <strong>{s.name}</strong>
          {s.target && s.target !== s.name && <span className="ui-muted mono"> → {s.target}</span>}
        </span>
        {s.phase === 'uploading' && props.onCancel && (
          <Button
            variant="danger"
            small
            onClick={props.onCancel}
            data-testid={props.testId ? `${props.testId}-cancel` : undefined}
            aria-label={`Cancel the upload of ${s.name}`}
          >
            Cancel
          </Button>
        )}
      </div>
      {(s.phase === 'uploading' || s.phase === 'verifying' || s.phase === 'done') && (
        <ProgressBar
          value={s.phase === 'verifying' ? null : s.phase === 'done' ? 1 : fraction}
          label={`Upload of ${s.name}`}
        />
      )}
      <div role="status" aria-live="polite" className="ui-upload-state">
        {s.phase === 'uploading' && (
          <span className="ui-muted">
            Uploading: {formatBytes(s.loaded)}
            {s.total > 0 ? ` of ${formatBytes(s.total)} (${Math.floor((fraction ?? 0) * 100)} %)` : ''}
          </span>
        )}
        {s.phase === 'verifying' && (
          <span className="ui-muted">{props.verifyingText ?? 'Sent; checking that it arrived…'}</span>
        )}
        {s.phase === 'done' && (
          <Notice tone="ok" title={props.doneTitle ?? 'Uploaded'} role="none">
            {s.message ?? `${s.name} uploaded.`}
          </Notice>
        )}
        {s.phase === 'cancelled' && (
          <Notice tone="info" title="Upload cancelled" role="none">
            {`${s.name} was not uploaded completely.`}
          </Notice>
        )}
      </div>
      {s.phase === 'failed' && (
        <Notice tone="bad" title={props.failedTitle ?? 'Upload failed'}>
          {s.message}
        </Notice>
      )}
    </div>
  );
}
